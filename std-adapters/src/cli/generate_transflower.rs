//! `duolando generate` on a Transflower model: R mode, the authors'
//! generation loop (models/util/generation.py, as inference/generate.py
//! runs it) over whole input arrays, one `--input MODALITY=FILE.npy` per
//! input modality of the model (the scaled features, e.g.
//! `expmap_scaled_20=seq.expmap_scaled_20.npy`; a style label as an
//! integer .npy of one value, or the integer itself). The base samples are
//! replayed from `--noise` ((N, C, H) float32: what the reference records,
//! tests/fixtures/transflower_*/noise.npy) or drawn from the engine's
//! seeded RNG (`--seed N`, default 0; not the authors' torch streams:
//! docs/TRANSFLOWER.md "Base distributions").
//!
//! Writes `output.npy`, (N, 1, C) float32: what generate.py
//! `--no-use_scalers` saves (`<seq>.<mod>.generated.npy`): frame t is song
//! row `output_time_offsets + t`, in the scaled feature space. With
//! `--scaler` (and optionally `--skeleton`) the frames are also unscaled
//! and placed on a skeleton, exported and shown
//! (`generate_transflower_motion`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use duolando_core::error::Error;
use duolando_core::format::DuoFile;
use duolando_core::transflower::config::TransflowerConfig;
use duolando_core::transflower::exact::{
    generate, generate_scratch_bytes, steps, Input, Replay, Seeded,
};
use duolando_core::transflower::model::Model;
use duolando_core::transflower::session::{session_bytes, Session, SessionConfig};

use super::generate::{Args, Mode};
use crate::engine_errors::{describe_transflower, describe_transflower_model};
use crate::npy::{read_f32_2d, read_i64_2d, write_f32};

/// One `--input` value: a modality's whole array.
enum Given {
    Rows {
        path: PathBuf,
        data: Vec<f32>,
        rows: usize,
    },
    Label(u32),
}

/// Refuses, by name, every flag of the other families.
fn refuse_other_flags(args: &Args) -> Result<()> {
    let model = args.model.display();
    let given: [(&str, bool); 6] = [
        ("--leader", args.leader.is_some()),
        ("--music", args.music.is_some()),
        ("--seed-tokens", args.seed_tokens.is_some()),
        ("--dance", args.dance.is_some()),
        ("--follower-start", args.follower_start.is_some()),
        ("--no-drain", args.no_drain),
    ];
    for (flag, on) in given {
        if on {
            let why = match flag {
                "--music" => "its inputs are given per modality with --input MODALITY=FILE.npy (the audio features included)",
                "--no-drain" => "a Transflower session has nothing to drain: each frame is final when its step runs",
                _ => "it is a Duolando / Bailando flag; Transflower takes --input MODALITY=FILE.npy per input modality and --noise or --seed",
            };
            bail!("{model} is a Transflower model: {flag} does not apply ({why})");
        }
    }
    if matches!(args.mode, Mode::Exact) {
        let b = &args.budget;
        if b.preset != "reference" || b.refresh.is_some() || b.kv.is_some() {
            bail!("{model}: --preset, --refresh and --kv set a streaming session (--mode streaming); --mode exact runs the authors' loop");
        }
    }
    // The other families' budget flags: refused by name.
    args.budget
        .transflower_config()
        .map(|_| ())
        .map_err(|e| anyhow::anyhow!("{model} is a Transflower model: {e}"))
}

/// The inputs in the model's order, each checked against its modality:
/// every modality given once, no other; widths; rows enough for the
/// window (and, for the inputs that slide, for every step); finite values.
fn read_inputs(args: &Args, cfg: &TransflowerConfig) -> Result<Vec<Given>> {
    let model = args.model.display();
    let names: Vec<&str> = cfg.inputs().iter().map(|i| i.name.as_str()).collect();
    let listing = || {
        cfg.inputs()
            .iter()
            .map(|i| {
                if i.is_discrete() {
                    format!("{} (a style label 0..{})", i.name.as_str(), i.tokens)
                } else {
                    format!(
                        "{} ({} columns, window {} rows)",
                        i.name.as_str(),
                        i.dim,
                        i.length
                    )
                }
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut given: Vec<Option<(String, &str)>> = vec![None; names.len()];
    for spec in &args.input {
        let Some((name, file)) = spec.split_once('=') else {
            bail!(
                "--input {spec:?}: expected MODALITY=FILE.npy; {model} takes {}",
                listing()
            );
        };
        let Some(i) = names.iter().position(|n| *n == name) else {
            bail!(
                "--input {spec:?}: {model} has no input modality `{name}`; it takes {}",
                listing()
            );
        };
        if given[i].is_some() {
            bail!("--input {spec:?}: modality `{name}` is given twice");
        }
        given[i] = Some((name.to_string(), file));
    }
    let mut out = Vec::with_capacity(names.len());
    for (i, (c, g)) in cfg.inputs().iter().zip(&given).enumerate() {
        let Some((name, file)) = g else {
            bail!("{model}: input modality `{}` is missing: give --input {}=FILE.npy (the model takes {})", names[i], names[i], listing());
        };
        if c.is_discrete() {
            let label: i64 = match file.parse::<i64>() {
                Ok(v) => v,
                Err(_) => {
                    let a =
                        read_i64_2d(Path::new(file), None, &format!("style label of `{name}`"))?;
                    if a.data.len() != 1 {
                        bail!(
                            "{file}: the style label of `{name}` is one integer, found {} values",
                            a.data.len()
                        );
                    }
                    a.data[0]
                }
            };
            if label < 0 || label >= c.tokens as i64 {
                bail!(
                    "{file}: style label {label} of `{name}` is outside 0..{}",
                    c.tokens
                );
            }
            out.push(Given::Label(label as u32));
            continue;
        }
        let path = PathBuf::from(file);
        let d = c.dim as usize;
        let a = read_f32_2d(&path, Some(d), &format!("`{name}` features (T, {d})"))?;
        if let Some(k) = a.data.iter().position(|v| !v.is_finite()) {
            bail!(
                "{}: `{name}` holds {} at row {}, column {} (inputs must be finite)",
                path.display(),
                a.data[k],
                k / d,
                k % d
            );
        }
        out.push(Given::Rows {
            path,
            data: a.data,
            rows: a.rows,
        });
    }
    // Rows: the output modality needs its whole window (the motion seed);
    // the last input sets the step count and needs the longest window; the
    // other sliding inputs need their window plus one row per further step.
    let row_count = |i: usize| match &out[i] {
        Given::Rows { rows, .. } => Some(*rows),
        Given::Label(_) => None,
    };
    let file_of = |i: usize| match &out[i] {
        Given::Rows { path, .. } => path.display().to_string(),
        Given::Label(_) => String::new(),
    };
    let m = cfg.output as usize;
    let lm = cfg.inputs[m].length as usize;
    if let Some(r) = row_count(m) {
        if r < lm {
            bail!("{}: the motion seed `{}` has {r} rows, the model's window needs {lm} (the authors' paper config would silently run a shorter window)", file_of(m), names[m]);
        }
    }
    let last = names.len() - 1;
    let max_l = cfg.max_window();
    let n = match row_count(last) {
        Some(r) if r < max_l => bail!(
            "{}: `{}` has {r} rows, at least {max_l} (the longest input window) are needed for one frame; the authors' generate.py says \"Sequence too short!\"",
            file_of(last),
            names[last]
        ),
        Some(r) => r - max_l + 1,
        None => 1,
    };
    for (i, c) in cfg.inputs().iter().enumerate() {
        let need = c.length as usize + n - 1;
        if let (Some(r), false) = (row_count(i), i == m) {
            if r < need {
                bail!(
                    "{}: `{}` has {r} rows; {n} steps (set by `{}`) need {need}",
                    file_of(i),
                    names[i],
                    names[last]
                );
            }
        }
    }
    Ok(out)
}

/// Reads `--noise`: (N, C, H) float32, N = the step count.
fn read_noise(path: &Path, cfg: &TransflowerConfig, n: usize) -> Result<Vec<f32>> {
    let (c, h) = (cfg.channels(), cfg.output_length as usize);
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let npy = npyz::NpyFile::new(bytes.as_slice())
        .with_context(|| format!("{} is not a valid .npy file", path.display()))?;
    let shape = npy.shape().to_vec();
    let want = [n as u64, c as u64, h as u64];
    if shape != want {
        bail!(
            "{}: base samples of shape {shape:?}; this run needs (steps, channels, frames per sample) = {want:?} (one (C, H) sample per generated frame, as the reference records them)",
            path.display()
        );
    }
    let data: Vec<f32> = match npy.dtype() {
        npyz::DType::Plain(ts)
            if ts.type_char() == npyz::TypeChar::Float && ts.size_field() == 4 =>
        {
            npy.into_vec::<f32>()?
        }
        other => bail!(
            "{}: expected float32 base samples, found dtype {}",
            path.display(),
            other.descr()
        ),
    };
    if let Some(k) = data.iter().position(|v| !v.is_finite()) {
        bail!(
            "{}: base sample value {} at flat index {k} is not finite",
            path.display(),
            data[k]
        );
    }
    Ok(data)
}

pub fn run_transflower(args: &Args, duo: &DuoFile<'_>) -> Result<()> {
    let model = Model::from_duo(duo).map_err(|e| {
        anyhow::anyhow!(
            "{}: {}",
            args.model.display(),
            describe_transflower_model(&e)
        )
    })?;
    refuse_other_flags(args)?;
    if args.noise.is_some() && args.seed.is_some() {
        bail!("give --noise (recorded base samples) or --seed (the engine's seeded sampler), not both");
    }
    let cfg = model.cfg;
    let given = read_inputs(args, &cfg)?;
    let motion = super::generate_transflower_motion::plan(
        args,
        cfg.channels(),
        cfg.output_input().name.as_str(),
    )?;
    let inputs: Vec<Input<'_>> = given
        .iter()
        .map(|g| match g {
            Given::Rows { data, .. } => Input::Rows(data),
            Given::Label(v) => Input::Label(*v),
        })
        .collect();
    let err =
        |e: duolando_core::error::Error| anyhow::anyhow!("{}", describe_transflower(&e, &cfg));
    let n = steps(&cfg, &inputs).map_err(err)?;
    let c = cfg.channels();
    let mut scratch =
        vec![0u8; generate_scratch_bytes(&cfg).context("the model's scratch plan overflows")?];
    let mut out = vec![0f32; n * c];
    let started = std::time::Instant::now();
    let noise = args
        .noise
        .as_ref()
        .map(|p| read_noise(p, &cfg, n))
        .transpose()?;
    let base = match (&args.mode, &args.noise) {
        (Mode::Streaming, _) => {
            let sc = args.budget.transflower_config()?;
            let seed = args.seed.unwrap_or(0);
            streaming(&model, &sc, &given, noise.as_deref(), seed, &mut out).map_err(err)?;
            let from = match &args.noise {
                Some(p) => format!("base samples replayed from {}", p.display()),
                None => format!("base samples drawn with seed {seed}"),
            };
            format!(
                "streaming session, preset {} (refresh {}, {:?} kept keys/values), {from}",
                args.budget.preset, sc.refresh, sc.kv
            )
        }
        (_, Some(p)) => {
            let noise = noise.as_deref().unwrap_or(&[]);
            generate(
                &model,
                &inputs,
                &mut Replay { noise },
                &mut scratch,
                &mut out,
            )
            .map_err(err)?;
            format!("base samples replayed from {}", p.display())
        }
        (_, None) => {
            let seed = args.seed.unwrap_or(0);
            generate(
                &model,
                &inputs,
                &mut Seeded::new(seed, &cfg),
                &mut scratch,
                &mut out,
            )
            .map_err(err)?;
            format!("base samples drawn with seed {seed}")
        }
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    write_f32(&args.out.join("output.npy"), &out, &[n, 1, c])?;
    eprintln!(
        "Transflower, {} mode: {n} frames of `{}` ({c} channels; frame 0 = song row {}), {base}; wrote {} in {:.1} s",
        if matches!(args.mode, Mode::Streaming) { "streaming" } else { "exact" },
        cfg.output_input().name.as_str(),
        cfg.output_time_offset,
        args.out.join("output.npy").display(),
        started.elapsed().as_secs_f64()
    );
    if let Some(plan) = &motion {
        let title = format!(
            "duolando: Transflower {}",
            args.model
                .file_name()
                .map(|f| f.to_string_lossy())
                .unwrap_or_default()
        );
        let files = super::generate_transflower_motion::write(plan, &args.out, &out, n, &title)?;
        eprintln!(
            "motion on a skeleton ({} frames at 20 fps): wrote {}",
            n,
            files.join(", ")
        );
    }
    Ok(())
}

/// S mode over whole arrays: the motion seed (the output modality's first
/// window), the labels, every sliding input pushed as the session has room,
/// stepped until its inputs run out; `out` (N, C) as R's.
fn streaming(
    model: &Model<'_>,
    sc: &SessionConfig,
    given: &[Given],
    noise: Option<&[f32]>,
    seed: u64,
    out: &mut [f32],
) -> Result<(), Error> {
    let cfg = &model.cfg;
    let c = cfg.channels();
    let m = cfg.output as usize;
    let lm = cfg.inputs[m].length as usize;
    let mut labels = Vec::new();
    let mut motion: &[f32] = &[];
    for (i, g) in given.iter().enumerate() {
        match g {
            Given::Label(v) => labels.push(*v),
            Given::Rows { data, .. } if i == m => motion = &data[..lm * c],
            Given::Rows { .. } => {}
        }
    }
    let mut arena = vec![0u8; session_bytes(cfg, sc)?];
    let mut s = Session::new(model, sc, motion, &labels, seed, &mut arena)?;
    let per_step = c * cfg.output_length as usize;
    let mut pushed = vec![0usize; given.len()];
    let n = out.len() / c;
    let mut made = 0;
    while made < n {
        for (i, g) in given.iter().enumerate() {
            if let (Given::Rows { data, rows, .. }, false) = (g, i == m) {
                let d = cfg.inputs[i].dim as usize;
                let k = s.room(i).min(rows - pushed[i]);
                s.push(i, &data[pushed[i] * d..(pushed[i] + k) * d])?;
                pushed[i] += k;
            }
        }
        let mut stepped = false;
        while made < n {
            let ok = match noise {
                Some(z) => s.step_with(&z[made * per_step..(made + 1) * per_step])?,
                None => s.step()?,
            };
            if !ok {
                break;
            }
            s.pull(&mut out[made * c..(made + 1) * c]);
            made += 1;
            stepped = true;
        }
        if !stepped {
            break;
        }
    }
    if made < n {
        return Err(Error::TooShort {
            buffer: duolando_core::error::Buffer::Features,
            frames: made,
            min: n,
        });
    }
    Ok(())
}
