//! Shared by the Transflower tests: the fixtures' cases (the authors'
//! state dict as a tensor source, inputs, noise, meta.json) and the error
//! metric rel = max |a - b| / max(1, max |b|).
#![allow(dead_code)]

use std::collections::HashMap;
use std::path::Path;

use duolando_core::nn::bind::TensorSource;
use duolando_core::tensor::{DType, TensorRef};
use duolando_core::transflower::config::TransflowerConfig;
use duolando_core::transflower::exact::Input;
use duolando_core::transflower::hparams::Hparams;
use duolando_core::transflower::model::Model;
use duolando_tests::fixture;

/// The authors' state dict as a tensor source (names unchanged, f32).
pub struct Weights {
    pub tensors: HashMap<String, (Vec<u32>, Vec<f32>)>,
}

impl Weights {
    pub fn load(path: &Path) -> Weights {
        let bytes = std::fs::read(path).unwrap();
        let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
        let mut tensors = HashMap::new();
        for (name, view) in st.tensors() {
            assert_eq!(view.dtype(), safetensors::Dtype::F32, "{name}");
            let data: Vec<f32> = view
                .data()
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            let shape = view.shape().iter().map(|&d| d as u32).collect();
            tensors.insert(name, (shape, data));
        }
        Weights { tensors }
    }
}

impl<'a> TensorSource<'a> for &'a Weights {
    fn tensor(&self, name: &str) -> Option<TensorRef<'a>> {
        let (shape, data) = self.tensors.get(name)?;
        let mut s = [1u32; 4];
        s[..shape.len()].copy_from_slice(shape);
        Some(TensorRef {
            dtype: DType::F32,
            rank: shape.len() as u8,
            shape: s,
            data: bytemuck::cast_slice(data),
        })
    }
}

pub fn npy_f32(path: &Path) -> (Vec<u64>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap();
    let f = npyz::NpyFile::new(bytes.as_slice()).unwrap();
    (f.shape().to_vec(), f.into_vec::<f32>().unwrap())
}

pub fn npy_i64(path: &Path) -> Vec<i64> {
    let bytes = std::fs::read(path).unwrap();
    npyz::NpyFile::new(bytes.as_slice())
        .unwrap()
        .into_vec::<i64>()
        .unwrap()
}

pub fn hparams(case: &str) -> Hparams {
    Hparams::parse(
        &std::fs::read_to_string(fixture(&format!("transflower_{case}/hparams.yaml"))).unwrap(),
    )
    .unwrap()
}

/// rel = max |a - b| / max(1, max |b|).
pub fn rel_err(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len(), "length");
    let mut abs = 0f32;
    let mut scale = 1f32;
    for (&x, &y) in a.iter().zip(b) {
        assert!(x.is_finite(), "non-finite value {x}");
        abs = abs.max((x - y).abs());
        scale = scale.max(y.abs());
    }
    abs / scale
}

pub struct Case {
    pub dir: std::path::PathBuf,
    pub meta: serde_json::Value,
    pub cfg: TransflowerConfig,
    pub weights: Weights,
    /// Per input: rows (continuous) or the label.
    pub inputs: Vec<Result<Vec<f32>, u32>>,
}

impl Case {
    pub fn load(case: &str) -> Case {
        let dir = fixture(&format!("transflower_{case}"));
        let meta: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("meta.json")).unwrap()).unwrap();
        let cfg = TransflowerConfig::from_hparams(&hparams(case)).unwrap();
        let weights = Weights::load(&dir.join("model.safetensors"));
        let inputs = cfg
            .inputs()
            .iter()
            .map(|i| {
                let p = dir.join(format!("in_{}.npy", i.name.as_str()));
                if i.is_discrete() {
                    Err(npy_i64(&p)[0] as u32)
                } else {
                    Ok(npy_f32(&p).1)
                }
            })
            .collect();
        Case {
            dir,
            meta,
            cfg,
            weights,
            inputs,
        }
    }
    pub fn inputs(&self) -> Vec<Input<'_>> {
        self.inputs
            .iter()
            .map(|x| match x {
                Ok(rows) => Input::Rows(rows),
                Err(label) => Input::Label(*label),
            })
            .collect()
    }
    pub fn model(&self) -> Model<'_> {
        Model::bind(&self.cfg, &&self.weights).unwrap()
    }
    pub fn noise(&self) -> Vec<f32> {
        npy_f32(&self.dir.join("noise.npy")).1
    }
    /// The reference's own float32-vs-float64 max difference over the steps.
    pub fn f32_vs_f64(&self) -> f32 {
        self.meta["f32_vs_f64_output_max_rel_err_per_step"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() as f32)
            .fold(0.0, f32::max)
    }
}
