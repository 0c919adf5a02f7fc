//! The crate's integration tests, one module per file, in one test binary: the crate's
//! code and its generic stack are compiled and linked once for all of them instead of
//! once per file (`cargo test -p oxicat-emu --test integration <module>::`).

mod axis_hub_image;
mod board_image;
mod cia402_image;
#[path = "../common/mod.rs"]
mod common;
mod exceptions;
mod laelaps_image;
mod laelaps_trot;
mod tue_es030_foe;
mod tue_es030_image;
