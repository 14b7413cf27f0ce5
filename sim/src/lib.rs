//! `ecmxf-sim`: a chip and EtherCAT network simulator for the ECM-XF.
//!
//! Not built yet (issue #3). Nothing here pretends to work: the crate exists
//! so the workspace layout is in place.
