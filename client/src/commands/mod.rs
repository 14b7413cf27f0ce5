//! One module per command (or family of commands), each with its JSON
//! report types next to the code that fills them.

pub mod alias;
pub mod cia402;
pub mod config;
pub mod crc;
pub mod cstruct;
pub mod data;
pub mod debug;
pub mod diag;
pub mod domains;
pub mod foe;
pub mod graph;
pub mod master;
pub mod pdo;
pub mod peripherals;
pub mod reg;
pub mod sdo;
pub mod sii;
pub mod slaves;
pub mod states;
pub mod version;
