//! Converter inputs (follower-GPT YAML + three safetensors), raw or as edits
//! of the tiny2 sources: YAML lines (values, deletions, duplicates,
//! indentation), safetensors JSON headers (dtype, shape, offsets, names,
//! entries), then bytes. And the invariant: [`check_convert`].

use std::path::Path;

use arbitrary::Arbitrary;
use duolando::convert::{convert_bytes, ConvertError, Sources};
use duolando::duo_writer::StoreAs;
use serde_json::Value;

use crate::bytes::{apply_all, ByteMutation, Int, Regions};
use crate::duo::{check_duo, DuoOutcome};
use crate::fixture::ConvertSources;

/// Scalars YAML and the config mapping get wrong.
pub const YAML_VALUES: [&str; 24] = [
    "0",
    "-1",
    "1",
    "3",
    "4294967295",
    "4294967296",
    "18446744073709551616",
    "1e400",
    "-0.0",
    "0.5",
    ".nan",
    ".inf",
    "~",
    "[]",
    "{}",
    "[1, 2",
    "\"a\"",
    "true",
    "&a 1",
    "*a",
    "!!binary AAAA",
    "0x10",
    "1_000",
    "999999999999",
];

/// One edit of the YAML text (`line` wraps around the lines).
#[derive(Arbitrary, Clone, Debug)]
pub enum YamlEdit {
    /// The value after the first `:` of the line becomes a special scalar.
    Value {
        line: u16,
        which: u8,
    },
    /// ... or an integer.
    Int {
        line: u16,
        value: Int,
        neg: bool,
    },
    Delete {
        line: u16,
    },
    Duplicate {
        line: u16,
    },
    Indent {
        line: u16,
        delta: i8,
    },
    Replace {
        line: u16,
        text: String,
    },
}

const DTYPES: [&str; 9] = [
    "F32", "F16", "BF16", "F64", "I64", "U8", "BOOL", "F8_E4M3", "Q",
];

/// One edit of a safetensors JSON header (`tensor` wraps around the entries
/// in name order).
#[derive(Arbitrary, Clone, Debug)]
pub enum StEdit {
    Dtype { tensor: u16, which: u8 },
    Dim { tensor: u16, axis: u8, value: Int },
    Rank { tensor: u16, rank: u8, fill: Int },
    Offset { tensor: u16, end: bool, value: Int },
    OffsetDelta { tensor: u16, end: bool, delta: i32 },
    NameOf { tensor: u16, other: u16 },
    Rename { tensor: u16, suffix: u8 },
    AddModulePrefix { tensor: u16 },
    Remove { tensor: u16 },
    Duplicate { tensor: u16 },
    Metadata { key: String, value: String },
}

/// A converter input.
#[derive(Arbitrary, Clone, Debug)]
pub enum ConvertInput {
    Raw {
        yaml: String,
        gpt: Vec<u8>,
        vqvae: Vec<u8>,
        transl: Vec<u8>,
        store: u8,
    },
    /// The tiny2 sources with edits; `file` picks the safetensors edited
    /// (0 gpt, 1 vqvae, 2 transl).
    Edited {
        yaml: Vec<YamlEdit>,
        file: u8,
        header: Vec<StEdit>,
        bytes: Vec<ByteMutation>,
        store: u8,
    },
}

fn store_as(s: u8) -> StoreAs {
    [
        StoreAs::F32,
        StoreAs::F16,
        StoreAs::Q8Block32,
        StoreAs::Q4Block32,
    ][s as usize % 4]
}

fn line_idx(n: usize, l: u16) -> Option<usize> {
    (n > 0).then(|| l as usize % n)
}

fn set_value(line: &str, v: &str) -> String {
    match line.find(':') {
        Some(i) => format!("{}: {v}", &line[..i]),
        None => format!("{line} {v}"),
    }
}

impl YamlEdit {
    pub fn apply(&self, lines: &mut Vec<String>) {
        let n = lines.len();
        match self {
            YamlEdit::Value { line, which } => {
                if let Some(i) = line_idx(n, *line) {
                    lines[i] =
                        set_value(&lines[i], YAML_VALUES[*which as usize % YAML_VALUES.len()]);
                }
            }
            YamlEdit::Int { line, value, neg } => {
                if let Some(i) = line_idx(n, *line) {
                    let v = if *neg {
                        format!("-{}", value.value())
                    } else {
                        value.value().to_string()
                    };
                    lines[i] = set_value(&lines[i], &v);
                }
            }
            YamlEdit::Delete { line } => {
                if let Some(i) = line_idx(n, *line) {
                    lines.remove(i);
                }
            }
            YamlEdit::Duplicate { line } => {
                if let Some(i) = line_idx(n, *line) {
                    let l = lines[i].clone();
                    lines.insert(i, l);
                }
            }
            YamlEdit::Indent { line, delta } => {
                if let Some(i) = line_idx(n, *line) {
                    let t = lines[i].trim_start().to_string();
                    let ind = (lines[i].len() - t.len()) as i32 + (*delta as i32 % 8);
                    lines[i] = format!("{}{t}", " ".repeat(ind.clamp(0, 64) as usize));
                }
            }
            YamlEdit::Replace { line, text } => {
                if let Some(i) = line_idx(n, *line) {
                    lines[i] = text.chars().take(200).collect();
                }
            }
        }
    }
}

/// Splits safetensors bytes into (JSON header, data); None if not well formed.
pub fn split_safetensors(b: &[u8]) -> Option<(serde_json::Map<String, Value>, &[u8])> {
    let n = u64::from_le_bytes(b.get(..8)?.try_into().ok()?) as usize;
    let json = b.get(8..8usize.checked_add(n)?)?;
    match serde_json::from_slice(json).ok()? {
        Value::Object(m) => Some((m, &b[8 + n..])),
        _ => None,
    }
}

/// Safetensors bytes from a JSON header and data.
pub fn join_safetensors(h: &serde_json::Map<String, Value>, data: &[u8]) -> (Vec<u8>, usize) {
    let json = serde_json::to_vec(h).expect("json");
    let mut out = (json.len() as u64).to_le_bytes().to_vec();
    out.extend_from_slice(&json);
    let header_end = out.len();
    out.extend_from_slice(data);
    (out, header_end)
}

fn key_at(h: &serde_json::Map<String, Value>, t: u16) -> Option<String> {
    let keys: Vec<&String> = h.keys().filter(|k| *k != "__metadata__").collect();
    (!keys.is_empty()).then(|| keys[t as usize % keys.len()].clone())
}

fn num(v: u64) -> Value {
    Value::from(v)
}

impl StEdit {
    pub fn apply(&self, h: &mut serde_json::Map<String, Value>) {
        let entry = |h: &mut serde_json::Map<String, Value>,
                     t: u16|
         -> Option<(String, serde_json::Map<String, Value>)> {
            let k = key_at(h, t)?;
            match h.get(&k)? {
                Value::Object(o) => Some((k, o.clone())),
                _ => None,
            }
        };
        match self {
            StEdit::Dtype { tensor, which } => {
                if let Some((k, mut o)) = entry(h, *tensor) {
                    o.insert(
                        "dtype".into(),
                        Value::from(DTYPES[*which as usize % DTYPES.len()]),
                    );
                    h.insert(k, Value::Object(o));
                }
            }
            StEdit::Dim {
                tensor,
                axis,
                value,
            } => {
                if let Some((k, mut o)) = entry(h, *tensor) {
                    if let Some(Value::Array(s)) = o.get_mut("shape") {
                        if !s.is_empty() {
                            let i = *axis as usize % s.len();
                            s[i] = num(value.value());
                        }
                    }
                    h.insert(k, Value::Object(o));
                }
            }
            StEdit::Rank { tensor, rank, fill } => {
                if let Some((k, mut o)) = entry(h, *tensor) {
                    if let Some(Value::Array(s)) = o.get_mut("shape") {
                        s.resize(*rank as usize % 9, num(fill.value()));
                    }
                    h.insert(k, Value::Object(o));
                }
            }
            StEdit::Offset { tensor, end, value } => {
                if let Some((k, mut o)) = entry(h, *tensor) {
                    if let Some(Value::Array(s)) = o.get_mut("data_offsets") {
                        if s.len() == 2 {
                            s[*end as usize] = num(value.value());
                        }
                    }
                    h.insert(k, Value::Object(o));
                }
            }
            StEdit::OffsetDelta { tensor, end, delta } => {
                if let Some((k, mut o)) = entry(h, *tensor) {
                    if let Some(Value::Array(s)) = o.get_mut("data_offsets") {
                        if s.len() == 2 {
                            let old = s[*end as usize].as_u64().unwrap_or(0);
                            s[*end as usize] = num(old.wrapping_add(*delta as i64 as u64));
                        }
                    }
                    h.insert(k, Value::Object(o));
                }
            }
            StEdit::NameOf { tensor, other } => {
                if let (Some((k, _)), Some((k2, o2))) = (entry(h, *tensor), entry(h, *other)) {
                    // The entry `k` now describes `k2`'s payload under its own name.
                    h.insert(k, Value::Object(o2));
                    let _ = k2;
                }
            }
            StEdit::Rename { tensor, suffix } => {
                if let Some((k, o)) = entry(h, *tensor) {
                    h.remove(&k);
                    h.insert(
                        format!(
                            "{k}{}",
                            ["_", ".weight", "x", ".0", ""][*suffix as usize % 5]
                        ),
                        Value::Object(o),
                    );
                }
            }
            StEdit::AddModulePrefix { tensor } => {
                if let Some((k, o)) = entry(h, *tensor) {
                    h.remove(&k);
                    h.insert(format!("module.{k}"), Value::Object(o));
                }
            }
            StEdit::Remove { tensor } => {
                if let Some(k) = key_at(h, *tensor) {
                    h.remove(&k);
                }
            }
            StEdit::Duplicate { tensor } => {
                if let Some((k, o)) = entry(h, *tensor) {
                    h.insert(format!("{k}.copy"), Value::Object(o));
                }
            }
            StEdit::Metadata { key, value } => {
                let mut m = serde_json::Map::new();
                m.insert(
                    key.chars().take(64).collect(),
                    Value::from(value.chars().take(64).collect::<String>()),
                );
                h.insert("__metadata__".into(), Value::Object(m));
            }
        }
    }
}

/// The four converter inputs an input describes.
pub struct Built {
    pub yaml: String,
    pub files: [Vec<u8>; 3],
    pub store: StoreAs,
}

pub fn build(input: &ConvertInput, base: &ConvertSources) -> Built {
    match input {
        ConvertInput::Raw {
            yaml,
            gpt,
            vqvae,
            transl,
            store,
        } => Built {
            yaml: yaml.clone(),
            files: [gpt.clone(), vqvae.clone(), transl.clone()],
            store: store_as(*store),
        },
        ConvertInput::Edited {
            yaml,
            file,
            header,
            bytes,
            store,
        } => {
            let mut lines: Vec<String> = base.yaml.lines().map(str::to_string).collect();
            for e in yaml.iter().take(16) {
                e.apply(&mut lines);
            }
            let mut files = [base.gpt.clone(), base.vqvae.clone(), base.transl.clone()];
            let f = *file as usize % 3;
            if !header.is_empty() || !bytes.is_empty() {
                let (mut h, data) = split_safetensors(&files[f]).expect("fixture safetensors");
                for e in header.iter().take(16) {
                    e.apply(&mut h);
                }
                let (mut out, header_end) = join_safetensors(&h, data);
                apply_all(
                    &mut out,
                    Regions {
                        prefix: 8,
                        header_end,
                    },
                    &bytes[..bytes.len().min(16)],
                );
                files[f] = out;
            }
            Built {
                yaml: lines.join("\n"),
                files,
                store: store_as(*store),
            }
        }
    }
}

/// The converter invariant: on any YAML text and any three byte strings,
/// `convert_bytes` answers without panicking; when it succeeds, its
/// output is a `.duo` that parses and binds.
pub fn check_convert(b: &Built) -> Result<usize, ConvertError> {
    let (g, v, t) = (
        Path::new("gpt.safetensors"),
        Path::new("vqvae.safetensors"),
        Path::new("transl.safetensors"),
    );
    let sources = Sources {
        gpt: (g, &b.files[0]),
        vqvae: (v, &b.files[1]),
        transl: (t, &b.files[2]),
    };
    let (bytes, _) = convert_bytes((Path::new("follower_gpt.yaml"), &b.yaml), &sources, b.store)?;
    let outcome = check_duo(&bytes);
    assert_eq!(
        outcome,
        DuoOutcome::Bound,
        "the converter wrote a .duo that does not bind"
    );
    Ok(bytes.len())
}
