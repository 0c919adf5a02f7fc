//! The crate's integration tests, one module per file, in one test binary: the crate's
//! code and its generic stack are compiled and linked once for all of them instead of
//! once per file (`cargo test -p oxicat-esi --test integration <module>::`).

mod additions;
mod axis_hub;
mod cia402;
mod demo;
mod fuzz_regressions;
mod identity_strings;
mod reference;
mod tue_es030;
