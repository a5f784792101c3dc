//! No build step: the build script exists so that `[build-dependencies]` in Cargo.toml pins
//! the features of the proc macros' `syn` to those of the CLI's and the Python wheel's builds, so
//! that each of them, built after another, reuses its compiled dependencies (tract included).

fn main() {}
