//! Typed helpers of the element-wise, linear-algebra and shape ops every target runtime runs
//! (see `offline/export/README.md`), and the attribute constructors.

use crate::error::ExportError;
use crate::graph::{GraphBuilder, Value};
use crate::pb;

impl GraphBuilder {
    /// `MatMul(a, b)` (numpy-style batched matrix product).
    pub fn matmul(&mut self, name: &str, a: &Value, b: &Value) -> Value {
        self.node("MatMul", name, &[a, b], vec![])
    }

    /// `Gemm(a, b, c)`: `alpha * a' @ b' + beta * c`, where `'` transposes when asked.
    /// `a` and `b` are 2-D; `c` broadcasts (unidirectionally) to the result.
    pub fn gemm(&mut self, name: &str, a: &Value, b: &Value, c: Option<&Value>, trans_b: bool) -> Value {
        let mut attrs = vec![attr_float("alpha", 1.0), attr_float("beta", 1.0)];
        if trans_b {
            attrs.push(attr_int("transB", 1));
        }
        match c {
            Some(c) => self.node("Gemm", name, &[a, b, c], attrs),
            None => self.node("Gemm", name, &[a, b], attrs),
        }
    }

    /// `Add(a, b)` with numpy broadcasting.
    pub fn add(&mut self, name: &str, a: &Value, b: &Value) -> Value {
        self.node("Add", name, &[a, b], vec![])
    }

    /// `Sub(a, b)` with numpy broadcasting.
    pub fn sub(&mut self, name: &str, a: &Value, b: &Value) -> Value {
        self.node("Sub", name, &[a, b], vec![])
    }

    /// `Mul(a, b)` with numpy broadcasting.
    pub fn mul(&mut self, name: &str, a: &Value, b: &Value) -> Value {
        self.node("Mul", name, &[a, b], vec![])
    }

    /// `Div(a, b)` with numpy broadcasting.
    pub fn div(&mut self, name: &str, a: &Value, b: &Value) -> Value {
        self.node("Div", name, &[a, b], vec![])
    }

    /// `Sigmoid(x)`.
    pub fn sigmoid(&mut self, name: &str, x: &Value) -> Value {
        self.node("Sigmoid", name, &[x], vec![])
    }

    /// `Tanh(x)`.
    pub fn tanh(&mut self, name: &str, x: &Value) -> Value {
        self.node("Tanh", name, &[x], vec![])
    }

    /// `LeakyRelu(x)` with slope `alpha` for negative inputs.
    pub fn leaky_relu(&mut self, name: &str, x: &Value, alpha: f32) -> Value {
        self.node("LeakyRelu", name, &[x], vec![attr_float("alpha", alpha)])
    }

    /// `Identity(x)`.
    pub fn identity(&mut self, name: &str, x: &Value) -> Value {
        self.node("Identity", name, &[x], vec![])
    }

    /// `Concat(values, axis)`.
    pub fn concat(&mut self, name: &str, values: &[&Value], axis: i64) -> Value {
        if values.is_empty() {
            self.fail(ExportError::InvalidOp {
                node: name.to_string(),
                message: "Concat needs at least one input".into(),
            });
        }
        self.node("Concat", name, values, vec![attr_int("axis", axis)])
    }

    /// `Slice(x, starts, ends, axes)` with unit steps; the index vectors become initializers
    /// `<name>.starts`, `<name>.ends`, `<name>.axes`.
    pub fn slice(&mut self, name: &str, x: &Value, axes: &[i64], starts: &[i64], ends: &[i64]) -> Value {
        if axes.len() != starts.len() || axes.len() != ends.len() {
            self.fail(ExportError::InvalidOp {
                node: name.to_string(),
                message: format!(
                    "Slice needs as many starts ({}) and ends ({}) as axes ({})",
                    starts.len(),
                    ends.len(),
                    axes.len()
                ),
            });
        }
        let s = self.i64_vector(name, "starts", starts);
        let e = self.i64_vector(name, "ends", ends);
        let a = self.i64_vector(name, "axes", axes);
        self.node("Slice", name, &[x, &s, &e, &a], vec![])
    }

    /// `Gather(x, indices, axis)` with constant indices (initializer `<name>.indices`).
    pub fn gather(&mut self, name: &str, x: &Value, indices: &[i64], axis: i64) -> Value {
        let i = self.i64_vector(name, "indices", indices);
        self.node("Gather", name, &[x, &i], vec![attr_int("axis", axis)])
    }

    /// `Split(x, split, axis)` into pieces of the given sizes (initializer `<name>.split`).
    /// Outputs are named `<name>.0`, `<name>.1`, ...
    pub fn split(&mut self, name: &str, x: &Value, sizes: &[usize], axis: i64) -> Vec<Value> {
        if sizes.is_empty() {
            self.fail(ExportError::InvalidOp {
                node: name.to_string(),
                message: "Split needs at least one size".into(),
            });
        }
        let sizes: Vec<i64> = sizes.iter().map(|&s| s as i64).collect();
        let s = self.i64_vector(name, "split", &sizes);
        let outs: Vec<String> = (0..sizes.len()).map(|i| format!("{name}.{i}")).collect();
        self.node_multi("Split", name, &[x, &s], &outs, vec![attr_int("axis", axis)])
    }

    /// `Reshape(x, shape)` (initializer `<name>.shape`; `0` copies a dimension, `-1` infers one).
    pub fn reshape(&mut self, name: &str, x: &Value, shape: &[i64]) -> Value {
        let s = self.i64_vector(name, "shape", shape);
        self.node("Reshape", name, &[x, &s], vec![])
    }

    /// `Unsqueeze(x, axes)` (initializer `<name>.axes`).
    pub fn unsqueeze(&mut self, name: &str, x: &Value, axes: &[i64]) -> Value {
        let a = self.i64_vector(name, "axes", axes);
        self.node("Unsqueeze", name, &[x, &a], vec![])
    }

    /// `Squeeze(x, axes)` (initializer `<name>.axes`).
    pub fn squeeze(&mut self, name: &str, x: &Value, axes: &[i64]) -> Value {
        let a = self.i64_vector(name, "axes", axes);
        self.node("Squeeze", name, &[x, &a], vec![])
    }

    /// `Softmax(x, axis)`.
    pub fn softmax(&mut self, name: &str, x: &Value, axis: i64) -> Value {
        self.node("Softmax", name, &[x], vec![attr_int("axis", axis)])
    }

    /// `LayerNormalization(x, scale, bias)` over the axes from `axis` on, with `epsilon`.
    pub fn layer_norm(&mut self, name: &str, x: &Value, scale: &Value, bias: &Value, axis: i64, epsilon: f32) -> Value {
        self.node(
            "LayerNormalization",
            name,
            &[x, scale, bias],
            vec![attr_int("axis", axis), attr_float("epsilon", epsilon)],
        )
    }

    /// `Abs(x)`.
    pub fn abs(&mut self, name: &str, x: &Value) -> Value {
        self.node("Abs", name, &[x], vec![])
    }

    /// `Shape(x)`: the dims of `x` as a 1-D i64 tensor.
    pub fn shape(&mut self, name: &str, x: &Value) -> Value {
        self.node("Shape", name, &[x], vec![])
    }

    /// `Range(start, limit, delta)` of i64 scalars (initializers `<name>.start` and
    /// `<name>.delta`; `limit` a scalar value of the graph, e.g. a dim read by
    /// [`GraphBuilder::shape`] and gathered with a scalar index).
    pub fn range_i64(&mut self, name: &str, start: i64, limit: &Value, delta: i64) -> Value {
        let s = self.initializer_i64(&format!("{name}.start"), &[], &[start]);
        let d = self.initializer_i64(&format!("{name}.delta"), &[], &[delta]);
        self.node("Range", name, &[&s, limit, &d], vec![])
    }

    /// `Gather(x, index, axis)` with one constant scalar index (initializer `<name>.index`): the
    /// result drops the axis.
    pub fn gather_scalar(&mut self, name: &str, x: &Value, index: i64, axis: i64) -> Value {
        let i = self.initializer_i64(&format!("{name}.index"), &[], &[index]);
        self.node("Gather", name, &[x, &i], vec![attr_int("axis", axis)])
    }

    /// `Cast(x)` to f32.
    pub fn cast_f32(&mut self, name: &str, x: &Value) -> Value {
        self.node("Cast", name, &[x], vec![attr_int("to", pb::tensor_proto::DataType::Float as i64)])
    }

    /// `Transpose(x, perm)`.
    pub fn transpose(&mut self, name: &str, x: &Value, perm: &[i64]) -> Value {
        self.node("Transpose", name, &[x], vec![attr_ints("perm", perm)])
    }
}

fn attr(name: &str, ty: pb::attribute_proto::AttributeType) -> pb::AttributeProto {
    pb::AttributeProto { name: name.to_string(), r#type: ty as i32, ..Default::default() }
}

/// A float attribute (its `type` field set, which tract requires).
pub fn attr_float(name: &str, f: f32) -> pb::AttributeProto {
    pb::AttributeProto { f, ..attr(name, pb::attribute_proto::AttributeType::Float) }
}

/// An int attribute.
pub fn attr_int(name: &str, i: i64) -> pb::AttributeProto {
    pb::AttributeProto { i, ..attr(name, pb::attribute_proto::AttributeType::Int) }
}

/// An ints attribute.
pub fn attr_ints(name: &str, ints: &[i64]) -> pb::AttributeProto {
    pb::AttributeProto { ints: ints.to_vec(), ..attr(name, pb::attribute_proto::AttributeType::Ints) }
}

/// A string attribute.
pub fn attr_string(name: &str, s: &str) -> pb::AttributeProto {
    pb::AttributeProto { s: s.as_bytes().to_vec(), ..attr(name, pb::attribute_proto::AttributeType::String) }
}
