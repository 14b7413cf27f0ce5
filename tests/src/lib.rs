//! End-to-end tests that start the real `ecmxfd` on the simulator.
//!
//! None yet: they arrive with the daemon (issue #4) and its API (issue #5).
