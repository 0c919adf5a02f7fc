//! The crate's integration tests, one module per file, in one test binary: the crate's
//! code and its generic stack are compiled and linked once for all of them instead of
//! once per file (`cargo test -p oxicat-slave --test integration <module>::`).

mod capacity;
#[path = "../common/mod.rs"]
mod common;
mod esm;
mod foe;
mod sdo;
mod sdo_info;
mod slot;
mod sync;
