//! Unity Inference Engine's documented ONNX operator support, as data: the list the portable
//! export ([`crate::portable`]) writes into.
//!
//! Source: the "Supported ONNX operators" page of Unity Inference Engine (package
//! `com.unity.ai.inference`) version 2.3.0,
//! <https://docs.unity3d.com/Packages/com.unity.ai.inference@2.3/manual/supported-operators.html>
//! (also at docs.unity.cn), read from the package's own `Documentation~/supported-operators.md`
//! at 2.3.0 (the needle-mirror/com.unity.ai.inference mirror, commit cc0730a4fba6e3836273bd7b63035b945e8637c7).
//! Each row keeps the page's three backend cells (the data types each backend runs, or "Not
//! supported"); the page's free-text notes are summarised in `docs/portable-export.md`.
//! The same version's "Supported models" page documents ONNX opsets 7 to 15
//! ([`UNITY_OPSET_MAX`]).

/// One row of the supported-operators table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UnityOp {
    /// ONNX operator name.
    pub name: &'static str,
    /// Data types with `BackendType.CPU` ("-" where the page gives none).
    pub cpu: &'static str,
    /// Data types with `BackendType.GPUCompute`.
    pub gpu_compute: &'static str,
    /// Data types with `BackendType.GPUPixel`.
    pub gpu_pixel: &'static str,
}

impl UnityOp {
    /// Whether every backend runs the op on float tensors (the page writes "-" for ops that
    /// are data-type independent, such as `Constant` and `Shape`).
    pub fn float_on_every_backend(&self) -> bool {
        [self.cpu, self.gpu_compute, self.gpu_pixel].iter().all(|c| *c == "-" || c.starts_with("float"))
    }
}

/// The package the list comes from.
pub const UNITY_PACKAGE: &str = "com.unity.ai.inference";
/// The package version the list comes from.
pub const UNITY_VERSION: &str = "2.3.0";
/// The documentation page the list comes from.
pub const UNITY_OPERATORS_URL: &str =
    "https://docs.unity3d.com/Packages/com.unity.ai.inference@2.3/manual/supported-operators.html";
/// Lowest ONNX opset the same version documents ("Supported models": opset 7 to 15).
pub const UNITY_OPSET_MIN: i64 = 7;
/// Highest ONNX opset the same version documents; later opsets "might still import, but results
/// can be unpredictable".
pub const UNITY_OPSET_MAX: i64 = 15;

/// The supported-operators table of Inference Engine 2.3.0 (134 rows; "Scatter" and
/// "Upsample" are marked deprecated there). One row per line, as on the page.
#[rustfmt::skip]
pub const UNITY_SUPPORTED_OPS: &[UnityOp] = &[
    UnityOp { name: "Abs", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Acos", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Acosh", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Add", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "And", cpu: "int", gpu_compute: "int", gpu_pixel: "int" },
    UnityOp { name: "ArgMax", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "ArgMin", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Asin", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Asinh", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Atan", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Atanh", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "AveragePool", cpu: "float", gpu_compute: "float (1D and 2D only)", gpu_pixel: "float (1D and 2D only)" },
    UnityOp { name: "BatchNormalization", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Bernoulli", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Cast", cpu: "float, int, short", gpu_compute: "float, int, short", gpu_pixel: "float, int, short" },
    UnityOp { name: "CastLike", cpu: "float, int, short", gpu_compute: "float, int, short", gpu_pixel: "float, int, short" },
    UnityOp { name: "Ceil", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Celu", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Clip", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Compress", cpu: "float, int", gpu_compute: "Not supported", gpu_pixel: "Not supported" },
    UnityOp { name: "Concat", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Constant", cpu: "-", gpu_compute: "-", gpu_pixel: "-" },
    UnityOp { name: "ConstantOfShape", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Conv", cpu: "float", gpu_compute: "float*", gpu_pixel: "float" },
    UnityOp { name: "ConvTranspose", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Cos", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Cosh", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "CumSum", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "DepthToSpace", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Div", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Dropout", cpu: "-", gpu_compute: "-", gpu_pixel: "-" },
    UnityOp { name: "Einsum", cpu: "float", gpu_compute: "float (1 or 2 inputs only)", gpu_pixel: "Not supported" },
    UnityOp { name: "Elu", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Equal", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Erf", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Exp", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Expand", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Flatten", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Floor", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Gather", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "GatherElements", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "GatherND", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Gemm", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "GlobalAveragePool", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "GlobalMaxPool", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Greater", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "GreaterOrEqual", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "GridSample", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Hardmax", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "HardSigmoid", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "HardSwish", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Identity", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "InstanceNormalization", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "IsInf", cpu: "float", gpu_compute: "float", gpu_pixel: "float (Infs not supported)" },
    UnityOp { name: "IsNaN", cpu: "float", gpu_compute: "float", gpu_pixel: "float (NaNs not supported)" },
    UnityOp { name: "LayerNormalization", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "LeakyRelu", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Less", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "LessOrEqual", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Log", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "LogSoftmax", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "LRN", cpu: "float", gpu_compute: "Not supported", gpu_pixel: "Not supported" },
    UnityOp { name: "LSTM", cpu: "float", gpu_compute: "float", gpu_pixel: "Not supported" },
    UnityOp { name: "MatMul", cpu: "float", gpu_compute: "float*", gpu_pixel: "float" },
    UnityOp { name: "Max", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "MaxPool", cpu: "float", gpu_compute: "float (1D and 2D only)", gpu_pixel: "float (1D and 2D only)" },
    UnityOp { name: "Mean", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Min", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Mod", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Mish", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Mul", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Multinomial", cpu: "float", gpu_compute: "Not supported", gpu_pixel: "Not supported" },
    UnityOp { name: "Neg", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "NonMaxSuppression", cpu: "float", gpu_compute: "float", gpu_pixel: "Not supported" },
    UnityOp { name: "NonZero", cpu: "float, int", gpu_compute: "Not supported", gpu_pixel: "Not supported" },
    UnityOp { name: "Not", cpu: "int", gpu_compute: "int", gpu_pixel: "int" },
    UnityOp { name: "OneHot", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Or", cpu: "int", gpu_compute: "int", gpu_pixel: "int" },
    UnityOp { name: "Pad", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Pow", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "PRelu", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "RandomNormal", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "RandomNormalLike", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "RandomUniform", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "RandomUniformLike", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Range", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Reciprocal", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "ReduceL1", cpu: "float, int", gpu_compute: "float*, int*", gpu_pixel: "float, int" },
    UnityOp { name: "ReduceL2", cpu: "float", gpu_compute: "float*", gpu_pixel: "float" },
    UnityOp { name: "ReduceLogSum", cpu: "float", gpu_compute: "float*", gpu_pixel: "float" },
    UnityOp { name: "ReduceLogSumExp", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "ReduceMax", cpu: "float, int", gpu_compute: "float*, int*", gpu_pixel: "float, int" },
    UnityOp { name: "ReduceMean", cpu: "float", gpu_compute: "float*", gpu_pixel: "float" },
    UnityOp { name: "ReduceMin", cpu: "float, int", gpu_compute: "float*, int*", gpu_pixel: "float, int" },
    UnityOp { name: "ReduceProd", cpu: "float, int", gpu_compute: "float*, int*", gpu_pixel: "float, int" },
    UnityOp { name: "ReduceSum", cpu: "float, int", gpu_compute: "float*, int*", gpu_pixel: "float, int" },
    UnityOp { name: "ReduceSumSquare", cpu: "float, int", gpu_compute: "float*, int*", gpu_pixel: "float, int" },
    UnityOp { name: "Relu", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Reshape", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Resize", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "RoiAlign", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Round", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Scatter", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "ScatterElements", cpu: "float, int", gpu_compute: "float, int (no ScatterReductionMode)", gpu_pixel: "float, int" },
    UnityOp { name: "ScatterND", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Selu", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Shape", cpu: "-", gpu_compute: "-", gpu_pixel: "-" },
    UnityOp { name: "Shrink", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Sigmoid", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Sign", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Sin", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Sinh", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Size", cpu: "-", gpu_compute: "-", gpu_pixel: "-" },
    UnityOp { name: "Slice", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Softmax", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Softplus", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Softsign", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "SpaceToDepth", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Split", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Sqrt", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Squeeze", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Sub", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Sum", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Tan", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Tanh", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "ThresholdedRelu", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Tile", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "TopK", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "Not supported" },
    UnityOp { name: "Transpose", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Trilu", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Unsqueeze", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Upsample", cpu: "float", gpu_compute: "float", gpu_pixel: "float" },
    UnityOp { name: "Where", cpu: "float, int", gpu_compute: "float, int", gpu_pixel: "float, int" },
    UnityOp { name: "Xor", cpu: "int", gpu_compute: "int", gpu_pixel: "int" },
];

/// The operators the same page lists as not supported (GRU, RNN, Scan, Loop and If among them).
pub const UNITY_UNSUPPORTED_OPS: &[&str] = &[
    "AffineGrid",
    "BitShift",
    "BitwiseAnd",
    "BitwiseNot",
    "BitwiseOr",
    "BitwiseXor",
    "CenterCropPad",
    "Col2Im",
    "ConcatFromSequence",
    "ConvInteger",
    "DeformConv",
    "DequantizeLinear",
    "Det",
    "DynamicQuantizeLinear",
    "EyeLike",
    "GlobalLpPool",
    "GroupNormalization",
    "GRU",
    "If",
    "ImageDecoder",
    "Loop",
    "LpNormalization",
    "LpPool",
    "MatMulInteger",
    "MaxRoiPool",
    "MaxUnpool",
    "MeanVarianceNormalization",
    "NegativeLogLikelihoodLoss",
    "Optional",
    "OptionalGetElement",
    "OptionalHasElement",
    "QLinearConv",
    "QLinearMatMul",
    "QuantizeLinear",
    "RegexFullMatch",
    "ReverseSequence",
    "RNN",
    "Scan",
    "SequenceAt",
    "SequenceConstruct",
    "SequenceEmpty",
    "SequenceErase",
    "SequenceInsert",
    "SequenceLength",
    "SequenceMap",
    "SoftmaxCrossEntropyLoss",
    "SplitToSequence",
    "StringConcat",
    "StringNormalizer",
    "StringSplit",
    "TfIdfVectorizer",
    "Unique",
];

/// The row of `op`, if the page lists it as supported.
pub fn unity_op(op: &str) -> Option<&'static UnityOp> {
    UNITY_SUPPORTED_OPS.iter().find(|o| o.name == op)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_list_is_the_pages_table() {
        assert_eq!(UNITY_SUPPORTED_OPS.len(), 134);
        for op in ["Gemm", "MatMul", "Sigmoid", "Tanh", "Split", "Gather", "Concat", "Unsqueeze", "Softmax"] {
            assert!(unity_op(op).is_some_and(|o| o.float_on_every_backend()), "{op}");
        }
        // LSTM is listed but not on GPUPixel; GRU, RNN, Scan, Loop and If are not listed.
        assert!(!unity_op("LSTM").unwrap().float_on_every_backend());
        for op in ["GRU", "RNN", "Scan", "Loop", "If"] {
            assert!(unity_op(op).is_none() && UNITY_UNSUPPORTED_OPS.contains(&op), "{op}");
        }
        let names: std::collections::HashSet<_> = UNITY_SUPPORTED_OPS.iter().map(|o| o.name).collect();
        assert_eq!(names.len(), UNITY_SUPPORTED_OPS.len(), "no duplicate rows");
    }
}
