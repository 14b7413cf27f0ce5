//! `ecmxfd`: the daemon that owns the ECM-XF chip.
//!
//! Not built yet (issue #4). Nothing here pretends to work: the crate exists
//! so the workspace layout is in place.
