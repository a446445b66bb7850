//! `.duo` inputs: raw bytes, or semantic edits of a valid file (the tiny2
//! fixture): config varints, tensor-table entries (dtype, dims, rank,
//! offsets, sizes, names, order, count), then byte edits. And the
//! invariant every input must satisfy: [`check_duo`].

use arbitrary::Arbitrary;
use duolando::duo_writer::{assemble, Header, HeaderEntry};
use duolando::model_file::AlignedBytes;
use duolando_core::bailando::model::Model as BailandoModel;
use duolando_core::duolando::model::Model;
use duolando_core::family::Family;
use duolando_core::format::{align_up, DuoFile, FormatError, PREFIX_LEN};
use duolando_core::nn::bind::BindError;
use duolando_core::tensor::DType;
use duolando_core::transflower::model::{
    Model as TransflowerModel, ModelError as TransflowerError,
};

use crate::bytes::{apply_all, varint_len, ByteMutation, Int, Regions};

/// One edit of the tensor table (`entry` indices wrap around the table).
#[derive(Arbitrary, Clone, Debug)]
pub enum EntryEdit {
    Dtype {
        entry: u16,
        code: u8,
    },
    Dim {
        entry: u16,
        axis: u8,
        value: Int,
    },
    Rank {
        entry: u16,
        rank: u8,
        fill: Int,
    },
    Offset {
        entry: u16,
        value: Int,
    },
    OffsetDelta {
        entry: u16,
        delta: i32,
    },
    Nbytes {
        entry: u16,
        value: Int,
    },
    NbytesDelta {
        entry: u16,
        delta: i32,
    },
    /// Give `entry` the name of `other` (duplicates, or a missing tensor).
    NameOf {
        entry: u16,
        other: u16,
    },
    NameByte {
        entry: u16,
        at: u8,
        byte: u8,
    },
    Remove {
        entry: u16,
    },
    Swap {
        a: u16,
        b: u16,
    },
    Duplicate {
        entry: u16,
    },
}

/// One edit of the postcard-encoded config: the `nth` varint (walking
/// the bytes as consecutive varints) becomes `value`.
#[derive(Arbitrary, Clone, Copy, Debug)]
pub struct ConfigEdit {
    pub nth: u8,
    pub value: Int,
}

/// A `.duo` input for the decoder.
#[derive(Arbitrary, Clone, Debug)]
pub enum DuoInput {
    Raw(Vec<u8>),
    /// The base file with these edits (config, table, then bytes).
    Edited {
        config: Vec<ConfigEdit>,
        table: Vec<EntryEdit>,
        bytes: Vec<ByteMutation>,
    },
    /// The base file re-encoded as format version 2 under family tag `tag`
    /// (0 Duolando, 1 Bailando: a config of one family under the other's
    /// tag; 2..: unknown families), then these edits.
    Family {
        tag: u8,
        config: Vec<ConfigEdit>,
        bytes: Vec<ByteMutation>,
    },
    /// The base file with weights overwritten by edge bit patterns (NaN,
    /// infinities, the largest finite values, subnormals): see [`poison`].
    Weights(Vec<WeightEdit>),
}

/// One f32 / f16 weight of the base file overwritten: element `element`
/// (wrapping) of table entry `entry` (wrapping; entries of other dtypes are
/// left alone) becomes bit pattern `pattern` (wrapping over
/// [`F32_PATTERNS`] / [`F16_PATTERNS`]).
#[derive(Arbitrary, Clone, Copy, Debug)]
pub struct WeightEdit {
    pub entry: u16,
    pub element: u32,
    pub pattern: u8,
}

/// f32 patterns: the first [`NON_FINITE`] are NaN (quiet, negative,
/// signalling, all ones) or infinite, the rest finite edge values (MAX,
/// MIN, the smallest subnormal, -0).
pub const F32_PATTERNS: [u32; 10] = [
    0x7fc0_0000,
    0xffc0_0000,
    0x7f80_0001,
    0xffff_ffff,
    0x7f80_0000,
    0xff80_0000,
    0x7f7f_ffff,
    0xff7f_ffff,
    0x0000_0001,
    0x8000_0000,
];
/// The f16 patterns, in the same classes.
pub const F16_PATTERNS: [u16; 10] = [
    0x7e00, 0xfe00, 0x7c01, 0xffff, 0x7c00, 0xfc00, 0x7bff, 0xfbff, 0x0001, 0x8000,
];
/// Patterns `0..NON_FINITE` of both lists are NaN or infinite.
pub const NON_FINITE: usize = 6;

/// The base file with `edits` applied to its data section (at most 16),
/// and the weight `parse` must name: the first non-finite one in table
/// order, then element order (`None`: every weight finite, the file valid).
pub fn poison(edits: &[WeightEdit], base: &Parts) -> (Vec<u8>, Option<(u32, u64)>) {
    let mut data = base.data.clone();
    let n = base.entries.len();
    let mut planted: Vec<(u32, u64, bool)> = Vec::new();
    for w in edits.iter().take(16) {
        let Some(i) = at(n, w.entry) else { continue };
        let e = &base.entries[i];
        let width = match e.dtype {
            0 => 4,
            1 => 2,
            _ => continue,
        };
        let numel = e.nbytes / width;
        if numel == 0 {
            continue;
        }
        let el = w.element as u64 % numel;
        let k = w.pattern as usize % F32_PATTERNS.len();
        let at = (e.offset + el * width) as usize;
        if width == 4 {
            data[at..at + 4].copy_from_slice(&F32_PATTERNS[k].to_le_bytes());
        } else {
            data[at..at + 2].copy_from_slice(&F16_PATTERNS[k].to_le_bytes());
        }
        // A later edit of the same element replaces an earlier one.
        planted.retain(|&(pi, pe, _)| (pi, pe) != (i as u32, el));
        planted.push((i as u32, el, k < NON_FINITE));
    }
    let want = planted
        .iter()
        .filter(|p| p.2)
        .map(|&(i, el, _)| (i, el))
        .min();
    let p = Parts {
        data,
        ..base.clone()
    };
    let header = header_bytes(&p);
    (
        duolando::duo_writer::assemble_raw_version(p.version, &header, &p.data).expect("assemble"),
        want,
    )
}

/// The pieces of a valid `.duo` file, editable.
#[derive(Clone, Debug)]
pub struct Parts {
    /// Format version of the prefix (1: `config_bytes` is a Duolando
    /// config; 2: the family tag varint, then that family's config).
    pub version: u32,
    pub config_bytes: Vec<u8>,
    pub entries: Vec<HeaderEntry>,
    pub data: Vec<u8>,
}

/// Splits a valid `.duo` file into config, table and data section.
pub fn split(bytes: &[u8]) -> Parts {
    let aligned = AlignedBytes::copy_from(bytes);
    let file = DuoFile::parse(aligned.as_bytes()).expect("base .duo parses");
    let version = file.prefix().version;
    let config_bytes = match (version, file.config().duolando()) {
        (duolando_core::format::VERSION_DUOLANDO, Some(c)) => postcard::to_stdvec(c),
        _ => postcard::to_stdvec(file.config()),
    }
    .expect("config encodes");
    let entries = file
        .tensors()
        .map(|e| HeaderEntry {
            name: e.name.to_string(),
            dtype: e.dtype as u8,
            shape: e.dims().to_vec(),
            offset: e.offset,
            nbytes: e.nbytes,
        })
        .collect();
    let header_len = u64::from_le_bytes(bytes[16..24].try_into().unwrap());
    let data_start = align_up(PREFIX_LEN as u64 + header_len).unwrap() as usize;
    Parts {
        version,
        config_bytes,
        entries,
        data: bytes[data_start..].to_vec(),
    }
}

fn at(n: usize, i: u16) -> Option<usize> {
    (n > 0).then(|| i as usize % n)
}

/// Header bytes: config, varint count, entries (exactly as the writer encodes them).
fn header_bytes(p: &Parts) -> Vec<u8> {
    #[derive(serde::Serialize)]
    struct Table<'a> {
        tensors: &'a [HeaderEntry],
    }
    let mut out = p.config_bytes.clone();
    out.extend(
        postcard::to_stdvec(&Table {
            tensors: &p.entries,
        })
        .expect("table encodes"),
    );
    out
}

impl EntryEdit {
    pub fn apply(&self, e: &mut Vec<HeaderEntry>) {
        let n = e.len();
        match *self {
            EntryEdit::Dtype { entry, code } => {
                if let Some(i) = at(n, entry) {
                    e[i].dtype = code % 7;
                }
            }
            EntryEdit::Dim { entry, axis, value } => {
                if let Some(i) = at(n, entry) {
                    let r = e[i].shape.len();
                    if r > 0 {
                        e[i].shape[axis as usize % r] = value.value() as u32;
                    }
                }
            }
            EntryEdit::Rank { entry, rank, fill } => {
                if let Some(i) = at(n, entry) {
                    e[i].shape.resize(rank as usize % 7, fill.value() as u32);
                }
            }
            EntryEdit::Offset { entry, value } => {
                if let Some(i) = at(n, entry) {
                    e[i].offset = value.value();
                }
            }
            EntryEdit::OffsetDelta { entry, delta } => {
                if let Some(i) = at(n, entry) {
                    e[i].offset = e[i].offset.wrapping_add(delta as i64 as u64);
                }
            }
            EntryEdit::Nbytes { entry, value } => {
                if let Some(i) = at(n, entry) {
                    e[i].nbytes = value.value();
                }
            }
            EntryEdit::NbytesDelta { entry, delta } => {
                if let Some(i) = at(n, entry) {
                    e[i].nbytes = e[i].nbytes.wrapping_add(delta as i64 as u64);
                }
            }
            EntryEdit::NameOf { entry, other } => {
                if let (Some(i), Some(j)) = (at(n, entry), at(n, other)) {
                    e[i].name = e[j].name.clone();
                }
            }
            EntryEdit::NameByte { entry, at: k, byte } => {
                if let Some(i) = at(n, entry) {
                    let mut b = e[i].name.clone().into_bytes();
                    if !b.is_empty() {
                        let k = k as usize % b.len();
                        b[k] = byte;
                    }
                    // Keep it a String (postcard needs UTF-8); invalid bytes become U+FFFD.
                    e[i].name = String::from_utf8_lossy(&b).into_owned();
                }
            }
            EntryEdit::Remove { entry } => {
                if let Some(i) = at(n, entry) {
                    e.remove(i);
                }
            }
            EntryEdit::Swap { a, b } => {
                if let (Some(i), Some(j)) = (at(n, a), at(n, b)) {
                    e.swap(i, j);
                }
            }
            EntryEdit::Duplicate { entry } => {
                if let Some(i) = at(n, entry) {
                    let d = e[i].clone();
                    e.insert(i, d);
                }
            }
        }
    }
}

impl ConfigEdit {
    pub fn apply(&self, cfg: &mut Vec<u8>) {
        let mut pos = 0;
        for _ in 0..self.nth {
            if pos >= cfg.len() {
                break;
            }
            pos += varint_len(&cfg[pos..]);
        }
        if pos >= cfg.len() {
            return;
        }
        let old = varint_len(&cfg[pos..]);
        let mut new = Vec::new();
        crate::bytes::varint(self.value.value(), &mut new);
        cfg.splice(pos..pos + old, new);
    }
}

/// The bytes `input` describes (`base` = the split of a valid file).
pub fn build(input: &DuoInput, base: &Parts) -> Vec<u8> {
    match input {
        DuoInput::Raw(b) => b.clone(),
        DuoInput::Edited {
            config,
            table,
            bytes,
        } => {
            let mut p = base.clone();
            for c in config.iter().take(16) {
                c.apply(&mut p.config_bytes);
            }
            for t in table.iter().take(32) {
                t.apply(&mut p.entries);
            }
            let header = header_bytes(&p);
            let header_end = PREFIX_LEN + header.len();
            let mut out = duolando::duo_writer::assemble_raw_version(p.version, &header, &p.data)
                .expect("assemble");
            apply_all(
                &mut out,
                Regions {
                    prefix: PREFIX_LEN,
                    header_end,
                },
                &bytes[..bytes.len().min(16)],
            );
            out
        }
        DuoInput::Family { tag, config, bytes } => {
            let mut p = base.clone();
            if p.version == duolando_core::format::VERSION_DUOLANDO {
                p.config_bytes.insert(0, 0);
                p.version = duolando_core::format::VERSION;
            }
            // One-byte varint tags: 0..=127 (the tiny2 base's tag is 0).
            p.config_bytes[0] = tag % 128;
            for c in config.iter().take(16) {
                c.apply(&mut p.config_bytes);
            }
            let header = header_bytes(&p);
            let header_end = PREFIX_LEN + header.len();
            let mut out = duolando::duo_writer::assemble_raw_version(p.version, &header, &p.data)
                .expect("assemble");
            apply_all(
                &mut out,
                Regions {
                    prefix: PREFIX_LEN,
                    header_end,
                },
                &bytes[..bytes.len().min(16)],
            );
            out
        }
        DuoInput::Weights(edits) => poison(edits, base).0,
    }
}

/// [`check_duo`] on the bytes of `input`, plus, for [`DuoInput::Weights`],
/// the answer it must give: the first non-finite weight named by table
/// index and element (`FormatError::NonFiniteWeight`), else the base
/// file's (bound; for Transflower, or a refusal of a flow weight's value).
/// Panics on a violation.
pub fn check_input(input: &DuoInput, base: &Parts) -> DuoOutcome {
    let DuoInput::Weights(edits) = input else {
        return check_duo(&build(input, base));
    };
    let (bytes, want) = poison(edits, base);
    let outcome = check_duo(&bytes);
    match want {
        Some((index, element)) => assert!(
            matches!(outcome, DuoOutcome::Rejected(FormatError::NonFiniteWeight { index: i, element: e, .. }) if (i, e) == (index, element)),
            "a NaN or infinite weight at tensor #{index} element {element}: {outcome:?}"
        ),
        // Finite values bind, except where a family checks weight values
        // beyond finiteness: Transflower's flow refuses a negative running
        // variance, a zero divisor, a non-permutation or a sign not +-1 by
        // tensor name (`ModelError::Value`).
        None => assert!(
            matches!(
                outcome,
                DuoOutcome::Bound | DuoOutcome::UnboundTransflower(TransflowerError::Value { .. })
            ),
            "only finite weights written: {outcome:?}"
        ),
    }
    outcome
}

/// How far an input got.
#[derive(Clone, Debug, PartialEq)]
pub enum DuoOutcome {
    Rejected(FormatError),
    /// Parsed and every tensor readable, but binding failed.
    Unbound(BindError),
    /// A Transflower file parsed but its model refused a config or a flow
    /// weight value (`transflower::model::ModelError` other than a bind error).
    UnboundTransflower(TransflowerError),
    Bound,
}

/// The decoder invariant: on any bytes, `DuoFile::parse` answers without
/// panicking; when it accepts, every listed tensor is readable with its
/// listed dtype and payload size, every f32 / f16 weight is finite, and
/// `Model::from_duo` answers without panicking. Panics (the fuzz/test failure) on a violation.
pub fn check_duo(bytes: &[u8]) -> DuoOutcome {
    let aligned = AlignedBytes::copy_from(bytes);
    let file = match DuoFile::parse(aligned.as_bytes()) {
        Ok(f) => f,
        Err(e) => return DuoOutcome::Rejected(e),
    };
    for entry in file.tensors() {
        let t = file
            .tensor(entry.name)
            .expect("a listed tensor must be readable");
        assert_eq!(t.dtype, entry.dtype, "{}", entry.name);
        assert_eq!(t.dims(), entry.dims(), "{}", entry.name);
        // An accepted file holds finite weights only (checked here by
        // value, independently of parse's bit test).
        let finite = match t.dtype {
            DType::F32 => t
                .data
                .chunks_exact(4)
                .all(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]).is_finite()),
            DType::F16 => t
                .data
                .chunks_exact(2)
                .all(|c| half::f16::from_le_bytes([c[0], c[1]]).is_finite()),
            _ => true,
        };
        assert!(
            finite,
            "{}: a NaN or infinite weight was accepted",
            entry.name
        );
    }
    // A parsed file binds as its own family (and is refused, by family,
    // as the other).
    // Transflower's binder has its own error (config and flow-value
    // problems besides BindError).
    let tf = || {
        TransflowerModel::from_duo(&file)
            .map(|_| ())
            .map_err(|e| match e {
                TransflowerError::Bind(b) => DuoOutcome::Unbound(b),
                other => DuoOutcome::UnboundTransflower(other),
            })
    };
    let plain = |r: Result<(), BindError>| r.map_err(DuoOutcome::Unbound);
    let own = match file.config().family() {
        Family::Duolando => plain(Model::from_duo(&file).map(|_| ())),
        Family::Bailando => plain(BailandoModel::from_duo(&file).map(|_| ())),
        Family::Transflower => tf(),
    };
    let others: [Result<(), DuoOutcome>; 2] = match file.config().family() {
        Family::Duolando => [plain(BailandoModel::from_duo(&file).map(|_| ())), tf()],
        Family::Bailando => [plain(Model::from_duo(&file).map(|_| ())), tf()],
        Family::Transflower => [
            plain(Model::from_duo(&file).map(|_| ())),
            plain(BailandoModel::from_duo(&file).map(|_| ())),
        ],
    };
    for other in others {
        assert!(
            matches!(other, Err(DuoOutcome::Unbound(BindError::Family { .. }))),
            "a {:?} file bound as another family",
            file.config().family()
        );
    }
    match own {
        Ok(()) => DuoOutcome::Bound,
        Err(e) => e,
    }
}

/// Re-export for tests that build headers by hand.
pub fn assemble_header(header: &Header, data: &[u8]) -> Vec<u8> {
    assemble(header, data).expect("assemble")
}
