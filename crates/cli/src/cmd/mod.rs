//! One module per subcommand.

pub mod bench;
pub mod data;
pub mod train;
pub mod render;
