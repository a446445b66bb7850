//! `duolando bench --family transflower`: Transflower's published paper
//! config (training/hparams/dance_combined/transflower_expmap.yaml: dhid
//! 800, 12 cross-modal layers, 16 flow steps; 122.3 M parameters) with
//! seeded random weights, per weight type: one R step (both input
//! transformers over their windows, the cross-modal transformer, the flow)
//! per thread count, against real time (one frame per 50 ms at 20 fps),
//! and one S step per session preset (the stale-rows mode's steps between
//! refreshes, the refreshes included in p99 and the mean), with the
//! session's arena.

use std::time::Instant;

use anyhow::{anyhow, Context};
use duolando_core::arena::Arena;
use duolando_core::transflower::config::TransflowerConfig;
use duolando_core::transflower::encoders::Window;
use duolando_core::transflower::exact::{prepare, step, Prepared, StepScratch};
use duolando_core::transflower::hparams::Hparams;
use duolando_core::transflower::model::Model;
use duolando_core::transflower::probe;
use duolando_core::transflower::session::{session_bytes, Preset, Session, SessionConfig};

use super::ort::OrtBaseline;
use super::LABEL;
use super::{on_threads, r_step_json, s_step_json, stats, Args, RandomModel, Rng, StoreAs};

/// Multiply-accumulates of one R step at the published size (the authors'
/// FlopCounter: 16.1 GMAC per frame).
const R_STEP_GMAC: f64 = 16.1;

/// The paper config's options (transflower_expmap.yaml; the flow's width
/// and heads as its checkpoint: `dhid_flow` 512, `num_heads_flow` 8).
pub fn published_paper() -> anyhow::Result<TransflowerConfig> {
    let mut h = Hparams::default();
    for (k, v) in [
        ("model", "transflower"),
        ("dins", "69,85"),
        ("douts", "69"),
        ("input_modalities", "expmap_scaled_20,audio_feats_scaled_20"),
        ("output_modalities", "expmap_scaled_20"),
        ("input_lengths", "120,140"),
        ("output_lengths", "3"),
        ("output_time_offsets", "120"),
        ("nlayers", "12"),
        ("nhead", "10"),
        ("scales", "'[[16,0]]'"),
        ("num_glow_coupling_blocks", "2"),
        ("glow_use_attn", "true"),
        ("use_transformer_nn", "true"),
        ("use_pos_emb_coupling", "true"),
        ("dhid", "800"),
        ("dhid_flow", "512"),
        ("num_heads_flow", "8"),
        ("cond_concat_dims", "true"),
        ("glow_norm_layer", "batchnorm"),
    ] {
        h.set(k, v).map_err(|e| anyhow!("hparams {k}: {e:?}"))?;
    }
    TransflowerConfig::from_hparams(&h).map_err(|e| anyhow!("published config: {e:?}"))
}

impl RandomModel {
    /// An f32 tensor's values, to overwrite.
    fn f32_mut(&mut self, name: &str) -> Option<&mut [f32]> {
        let (dtype, _, _, range) = self.table.get(name)?.clone();
        if dtype != duolando_core::tensor::DType::F32 {
            return None;
        }
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut self.buf);
        Some(bytemuck::cast_slice_mut(&mut bytes[range]))
    }
}

/// Random weights the flow can invert: each 1x1 conv's `p` the identity,
/// `sign_s` 1, running variances 1, norm scales and `weight_v` away from 0.
fn flow_ready(rm: &mut RandomModel) {
    let names: Vec<String> = rm.table.keys().cloned().collect();
    for name in names {
        let Some(v) = rm.f32_mut(&name) else { continue };
        if name.ends_with(".p") {
            let c = (v.len() as f64).sqrt() as usize;
            v.fill(0.0);
            for i in 0..c {
                v[i * c + i] = 1.0;
            }
        } else if name.ends_with(".sign_s") || name.ends_with(".running_var") {
            v.fill(1.0);
        } else if name.ends_with(".gamma") || name.ends_with(".weight_v") || name.ends_with(".inv_std") || name.ends_with(".weight_g") {
            for x in v.iter_mut() {
                *x += 1.0;
            }
        }
    }
}

/// The bench; `ort`: onnxruntime's figures for the same R step
/// (tools/transflower_ort_r_step.py), printed with the ratios.
pub(super) fn run(args: &Args, ort: Option<&OrtBaseline>, j: &mut serde_json::Map<String, serde_json::Value>) -> anyhow::Result<()> {
    let cfg = published_paper()?;
    let c = cfg.channels();
    let h = cfg.output_length as usize;
    let real_time_ms = 1000.0 / duolando_core::transflower::config::FPS as f64;
    let mut rng = Rng(0x7f10_3e75);
    // Inputs in the scaled feature space: ~N(0, 1)-sized rows.
    let motion: Vec<f32> = (0..cfg.inputs[0].length as usize * c).map(|_| rng.next()).collect();
    let audio_d = cfg.inputs[1].dim as usize;
    let audio_rows = cfg.inputs[1].length as usize + args.s_steps.max(64) + 64;
    let audio: Vec<f32> = (0..audio_rows * audio_d).map(|_| rng.next()).collect();
    let z: Vec<f32> = (0..c * h).map(|_| 0.5 * rng.next()).collect();
    let mut medians = super::ort::RStepMedians::default();
    if let Some(o) = ort {
        o.print("Transflower R step");
    }
    for d in &args.dtypes {
        let store_as = match d.as_str() {
            "f32" => StoreAs::F32,
            "f16" => StoreAs::F16,
            "int8" => StoreAs::Q8Block32x8,
            "q4" => StoreAs::Q4Block32x8,
            other => return Err(anyhow!("unknown dtype '{other}' (f32, f16, int8, q4)")),
        };
        let t0 = Instant::now();
        let mut rm = RandomModel::build(&cfg.into(), store_as, 0x7f10_0000 ^ store_as as u64)?;
        flow_ready(&mut rm);
        let model = Model::bind(&cfg, &&rm).map_err(|e| anyhow!("bind: {e:?}"))?;
        eprintln!("Transflower {d}: model built and bound in {:.1} s ({:.1} MB of weights)", t0.elapsed().as_secs_f64(), rm.weight_bytes() as f64 / 1e6);
        for &t in &args.threads {
            let times = on_threads(t, || {
                let mut buf = vec![0u8; 64 << 20];
                let mut a = Arena::new(&mut buf);
                let mut p = Prepared::carve(&mut a, &cfg).map_err(|e| anyhow!("{e:?}"))?;
                prepare(&model, &mut p);
                let mut s = StepScratch::carve(&mut a, &cfg).map_err(|e| anyhow!("{e:?}"))?;
                let windows = [Window::Rows(&motion), Window::Rows(&audio[..cfg.inputs[1].length as usize * audio_d])];
                let mut frames = vec![0f32; c * h];
                let mut v = Vec::new();
                for i in 0..args.warmup + args.runs {
                    let t0 = Instant::now();
                    step(&model, &p, &windows, &z, &mut s, &mut frames, &mut probe::none);
                    if i >= args.warmup {
                        v.push(t0.elapsed());
                    }
                }
                if !frames.iter().all(|x| x.is_finite()) {
                    return Err(anyhow!("non-finite frame"));
                }
                Ok(v)
            })?;
            let st = stats(times);
            let vs_f32 = medians.record(d, t, st.median_ms, ort);
            r_step_json(j, d, t, &st);
            say!(
                "Transflower R step {d:>4} t{t}: median {:8.1} ms  p99 {:8.1} ms  {:.1} GMAC/s  {:.2}x real time ({real_time_ms:.0} ms per frame){vs_f32}",
                st.median_ms,
                st.p99_ms,
                R_STEP_GMAC / st.median_ms * 1e3,
                real_time_ms / st.median_ms
            );
        }
        for preset in Preset::ALL {
            let sc = SessionConfig::preset(preset);
            let bytes = session_bytes(&cfg, &sc).map_err(|e| anyhow!("{e:?}"))?;
            for &t in &args.threads {
                // At least four refreshes, so p99 sees them.
                let n = (args.warmup + args.s_steps).max(4 * sc.refresh as usize + args.warmup);
                let times = on_threads(t, || {
                    let mut arena = vec![0u8; bytes];
                    let mut s = Session::new(&model, &sc, &motion, &[], 7, &mut arena).map_err(|e| anyhow!("{e:?}"))?;
                    let la = cfg.inputs[1].length as usize;
                    s.push(1, &audio[..(la - 1) * audio_d]).map_err(|e| anyhow!("{e:?}"))?;
                    let mut frame = vec![0f32; c];
                    let mut v = Vec::new();
                    for i in 0..n {
                        let row = (la - 1 + i) % audio_rows;
                        s.push(1, &audio[row * audio_d..(row + 1) * audio_d]).map_err(|e| anyhow!("{e:?}"))?;
                        let t0 = Instant::now();
                        let made = s.step().map_err(|e| anyhow!("{e:?}"))?;
                        s.pull(&mut frame);
                        if i >= args.warmup {
                            v.push(t0.elapsed());
                        }
                        if !made || !frame.iter().all(|x| x.is_finite()) {
                            return Err(anyhow!("step {i}: no frame or a non-finite one"));
                        }
                    }
                    Ok(v)
                })
                .with_context(|| format!("S step {}", preset.name()))?;
                let st = stats(times);
                s_step_json(j, d, t, preset.name(), &st, bytes);
                say!(
                    "Transflower S step {d:>4} t{t} {:<8} (refresh {:>2}{}, {:?} K/V): median {:8.2} ms  p99 {:8.2} ms  mean {:8.2} ms  {:.2}x real time (mean)  arena {:.2} MB",
                    preset.name(),
                    sc.refresh,
                    if sc.rolling { " rolling" } else { "" },
                    sc.kv,
                    st.median_ms,
                    st.p99_ms,
                    st.mean_ms,
                    real_time_ms / st.mean_ms,
                    bytes as f64 / 1e6
                );
            }
        }
    }
    if let Some(o) = ort {
        o.print_ratios("Transflower R step", &medians.ours);
        o.json(j, &medians.ours);
    }
    say!("Transflower: published paper config (transflower_expmap.yaml), seeded random weights (flow made invertible); R step = one generated frame of R mode; S step = one session step (audio row pushed, frame pulled); GMAC/s from the authors' 16.1 GMAC per frame; onnxruntime: --ort-json from tools/transflower_ort_r_step.py (the authors' modules, the same step).");
    Ok(())
}
