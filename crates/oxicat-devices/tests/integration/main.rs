//! The crate's integration tests, one module per file, in one test binary: the crate's
//! code and its generic stack are compiled and linked once for all of them instead of
//! once per file (`cargo test -p oxicat-devices --test integration <module>::`).

mod axis_hub_rig;
mod cia402_master;
mod cia402_rig;
mod demo_app;
mod exec_time;
mod handles;
mod laelaps_stack;
mod route_matrix;
mod trot;
mod tue_es030;
mod tue_es030_board;
mod twin_behaviour;
mod twin_catalogue;
