//! onnxruntime (through `ort`, `load-dynamic`) for the parity tests.
//!
//! `bash scripts/onnxruntime.sh` provisions `.onnxruntime/libonnxruntime.so.1.31.1` (or set
//! `ORT_DYLIB_PATH`). A missing library fails the calling test with these instructions.

use std::borrow::Cow;
use std::path::PathBuf;
use std::sync::OnceLock;
use zoo_export::OnnxModel;

/// The onnxruntime library: `ORT_DYLIB_PATH`, else `<workspace>/.onnxruntime/libonnxruntime.so.1.31.1`.
pub fn onnxruntime_library() -> PathBuf {
    let path = std::env::var_os("ORT_DYLIB_PATH")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../.onnxruntime/libonnxruntime.so.1.31.1"));
    // ort panics with "Failed to load ONNX Runtime dylib" on a missing file (DEPENDENCY-FACTS):
    // check first and say how to provision it.
    assert!(
        path.is_file(),
        "onnxruntime library not found at {}: run `bash scripts/onnxruntime.sh` from the workspace root \
         (it downloads the onnxruntime==1.31.1 wheel from PyPI and extracts the library), or set ORT_DYLIB_PATH",
        path.display()
    );
    path
}

/// The process-wide onnxruntime environment, loaded once from [`onnxruntime_library`].
pub fn ort_environment() -> &'static ort::environment::Environment {
    static ENV: OnceLock<ort::environment::Environment> = OnceLock::new();
    ENV.get_or_init(|| {
        let lib = onnxruntime_library();
        ort::init_from(&lib)
            .unwrap_or_else(|e| panic!("cannot load onnxruntime from {}: {e}", lib.display()))
            .build()
            .expect("onnxruntime environment")
    })
}

/// An onnxruntime session of `model`, run with named `[batch, width]` f32 inputs.
pub struct OrtSession(pub ort::session::Session);

impl OrtSession {
    /// A session of `model` on one thread.
    pub fn new(model: &OnnxModel) -> Self {
        let session = ort::session::Session::builder(ort_environment())
            .expect("session builder")
            .with_intra_threads(1)
            .expect("threads")
            .commit_from_memory(&model.to_bytes())
            .expect("onnxruntime loads the exported model");
        OrtSession(session)
    }

    /// Runs with named `[batch, width]` inputs; returns the named outputs, flattened.
    pub fn run(&mut self, inputs: &[(&str, usize, &[f32])], outputs: &[&str]) -> Vec<Vec<f32>> {
        let shapes: Vec<[usize; 2]> = inputs.iter().map(|(_, batch, data)| [*batch, data.len() / batch]).collect();
        let shaped: Vec<(&str, &[usize], &[f32])> =
            inputs.iter().zip(&shapes).map(|((name, _, data), shape)| (*name, &shape[..], *data)).collect();
        self.run_shaped(&shaped, outputs)
    }

    /// Runs with named inputs of any shape (`dims`, row-major values); returns the named
    /// outputs, flattened.
    pub fn run_shaped(&mut self, inputs: &[(&str, &[usize], &[f32])], outputs: &[&str]) -> Vec<Vec<f32>> {
        let values: Vec<(Cow<'_, str>, ort::session::SessionInputValue<'_>)> = inputs
            .iter()
            .map(|(name, dims, data)| {
                let shape: Vec<i64> = dims.iter().map(|d| *d as i64).collect();
                let t = ort::value::Tensor::from_array((shape, data.to_vec())).expect("tensor");
                (Cow::Owned(name.to_string()), t.into())
            })
            .collect();
        let out = self.0.run(values).expect("onnxruntime runs the graph");
        outputs.iter().map(|name| out[*name].try_extract_tensor::<f32>().expect("f32 output").1.to_vec()).collect()
    }

    /// A metadata_props value.
    pub fn metadata(&self, key: &str) -> Option<String> {
        self.0.metadata().expect("metadata").custom(key)
    }
}
