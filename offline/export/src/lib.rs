//! ONNX writer of zoo.
//!
//! Builds ONNX models (IR 8, default-domain opset 17) from Rust on the prost ONNX types of
//! [`zoo_format::pb`], and encodes them with prost (no tract: the model crates export without it). Graphs built this way
//! load in tract 0.23 and onnxruntime 1.31 (checked by `tests/parity.rs` of the workspace).
//!
//! Typed helpers exist for ops tract and onnxruntime run (see `offline/export/README.md` for the limits
//! of each runtime); [`portable`] rewrites a finished model into the operators Unity Inference
//! Engine documents ([`unity`]), recurrent nodes unrolled. Node, value and initializer names
//! are the readable paths the caller gives (the candle variable paths for weights), so a
//! graph viewer shows `frame_encoder.linear0.weight`, not `onnx::MatMul_17`.
//!
//! Building never panics: a mistake (a duplicate name, an initializer whose data does not
//! match its shape, a reference to an unknown value) is recorded and [`GraphBuilder::finish`]
//! returns it as an [`ExportError`].
//!
//! ```
//! use zoo_export::{Dim, GraphBuilder};
//! let mut g = GraphBuilder::new("toy");
//! let x = g.input("x", &[Dim::batch(), Dim::Fixed(2)]);
//! let w = g.initializer_f32("dense.weight", &[2, 3], &[1., 0., 0., 0., 1., 0.]);
//! let b = g.initializer_f32("dense.bias", &[3], &[0.1, 0.2, 0.3]);
//! let y = g.matmul("dense.matmul", &x, &w);
//! let y = g.add("dense.add", &y, &b);
//! g.output("y", &y, &[Dim::batch(), Dim::Fixed(3)]);
//! g.metadata("zoo.format_version", "2");
//! let model = g.finish().unwrap();
//! assert_eq!(model.summary().op_counts["MatMul"], 1);
//! let bytes = model.to_bytes();
//! assert!(!bytes.is_empty());
//! ```

//!
//! The crate knows no model and no candle: each model's graph definition lives beside its
//! candle forward pass (RTN's in `zoo_rtn::export`) and writes its metadata through the
//! format crate's types (`zoo_format`).

mod error;
mod graph;
mod model;
mod ops;
#[cfg(feature = "portable")]
pub mod portable;
mod recurrent;
mod summary;
pub mod unity;
mod width;

pub use error::ExportError;
pub use graph::{Dim, GraphBuilder, Value};
pub use model::OnnxModel;
pub use ops::{attr_float, attr_int, attr_ints, attr_string};
#[cfg(feature = "portable")]
pub use portable::{PortableModel, PortableOptions, to_portable};
pub use recurrent::{GRU_TORCH_TO_ONNX, LSTM_TORCH_TO_ONNX, RnnDirection, RnnInputs, RnnOutputs, reorder_gates};
pub use summary::{GraphSummary, summarize};
pub use width::{quantize_per_channel, weight_values, with_weights};
/// The widths [`with_weights`] writes (re-exported from zoo-format).
pub use zoo_format::WeightWidth;

/// The prost ONNX types (`ModelProto`, `NodeProto`, ...), re-exported from zoo-format.
pub use zoo_format::pb;

/// ONNX IR version written into every model.
pub const IR_VERSION: i64 = 8;
/// Opset of the default ONNX domain every model imports.
pub const OPSET: i64 = 17;
/// Name of the symbolic batch dimension of graph inputs and outputs.
pub const BATCH_DIM: &str = "batch";
