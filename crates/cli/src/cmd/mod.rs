//! One module per subcommand.

pub mod bench;
pub mod bench_runtime;
pub mod data;
pub mod data_luxo;
pub mod decompress;
pub mod export;
pub mod render;
pub mod train;
pub mod transition;
