//! Shared helpers of the integration tests: fixture paths, `.npy` loading,
//! tract-onnx as the golden reference, and named tolerances.

use std::path::{Path, PathBuf};

use tract_onnx::prelude::*;

/// `tests/fixtures/`.
pub fn fixtures_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures")
}

/// A fixture path under `tests/fixtures/`.
pub fn fixture(rel: &str) -> PathBuf {
    fixtures_dir().join(rel)
}

/// Named error limits (tract-style), so a tolerance is a decision with a name,
/// not a magic number at the call site.
#[derive(Clone, Copy, Debug)]
pub enum Tol {
    /// Module outputs vs the ONNX graph in tract: max |a-b| / max(1, max|b|).
    /// Issue #2 requires 1e-4.
    ModuleRel,
    /// Rollout motion vs golden: max |a-b| in metres. Issue #2 requires 1e-4.
    MotionAbs,
}

impl Tol {
    pub fn limit(self) -> f32 {
        match self {
            Tol::ModuleRel => 1e-4,
            Tol::MotionAbs => 1e-4,
        }
    }
}

/// Max absolute difference and the relative error scaled by max(1, max|expected|).
pub fn max_errors(actual: &[f32], expected: &[f32]) -> (f32, f32) {
    assert_eq!(actual.len(), expected.len(), "length mismatch");
    let mut max_abs = 0f32;
    let mut scale = 1f32;
    for (&a, &e) in actual.iter().zip(expected) {
        assert!(a.is_finite(), "non-finite output {a}");
        max_abs = max_abs.max((a - e).abs());
        scale = scale.max(e.abs());
    }
    (max_abs, max_abs / scale)
}

/// An ONNX graph loaded into tract, ready to run.
pub struct Onnx {
    plan: TypedRunnableModel<TypedModel>,
    pub path: PathBuf,
    /// False when tract's optimizer refused the graph and it runs decluttered.
    pub optimized: bool,
}

impl Onnx {
    pub fn load(path: &Path) -> Onnx {
        let typed = tract_onnx::onnx()
            .model_for_path(path)
            .and_then(|m| m.into_typed())
            .and_then(|m| m.into_decluttered())
            .unwrap_or_else(|e| panic!("tract cannot load {}: {e:?}", path.display()));
        // Optimized when tract can; tract 0.21's codegen trips on a token
        // embedding table read by a Gather ("Versatile packing" of the const),
        // so graphs with that pattern run decluttered (slower, same maths).
        let (model, optimized) = match typed.clone().into_optimized() {
            Ok(m) => (m, true),
            Err(_) => (typed, false),
        };
        let plan = model
            .into_runnable()
            .unwrap_or_else(|e| panic!("tract cannot plan {}: {e:?}", path.display()));
        Onnx { plan, path: path.to_path_buf(), optimized }
    }

    /// Runs the graph; inputs in declaration order.
    pub fn run(&self, inputs: Vec<Tensor>) -> Vec<Tensor> {
        let inputs: TVec<TValue> = inputs.into_iter().map(|t| t.into()).collect();
        self.plan
            .run(inputs)
            .unwrap_or_else(|e| panic!("tract run of {} failed: {e:?}", self.path.display()))
            .into_iter()
            .map(|v| v.into_tensor())
            .collect()
    }
}

/// An f32 tensor of the given shape.
pub fn tensor_f32(shape: &[usize], data: &[f32]) -> Tensor {
    Tensor::from_shape(shape, data).expect("shape")
}

/// An i64 tensor of the given shape.
pub fn tensor_i64(shape: &[usize], data: &[i64]) -> Tensor {
    Tensor::from_shape(shape, data).expect("shape")
}

/// Flat f32 contents of a tensor.
pub fn as_f32(t: &Tensor) -> Vec<f32> {
    t.as_slice::<f32>().expect("f32 output").to_vec()
}

/// Flat i64 contents of a tensor.
pub fn as_i64(t: &Tensor) -> Vec<i64> {
    t.as_slice::<i64>().expect("i64 output").to_vec()
}
