//! The corrupt-file catalogue (issue #6 item 2): one named test per
//! rejection rule of docs/FORMAT.md §5, each asserting the SPECIFIC
//! `FormatError` variant, built by mutating a valid small model that the
//! writer produced from seeded random weights; plus a property test that
//! random mutations and truncations never panic.
//!
//! Run: `cargo test -p duolando-tests --test corrupt_files`.

use duolando::duo_writer::{
    assemble, assemble_raw, write_duo, Header, HeaderEntry, StoreAs, Tensor,
};
use duolando::model_file::{AlignedBytes, ModelFile, ModelFileError};
use duolando_core::duolando::config::{GptConfig, LatConfig, ModelConfig, Part};
use duolando_core::duolando::schema::{for_each_tensor, tensor_count};
use duolando_core::format::{
    schema_tensor, DuoFile, FormatError, HeaderField, NonFiniteKind, Shape, MAX_DIM,
    MAX_HEADER_LEN, MAX_NAME_LEN, MAX_TENSORS,
};
use duolando_core::limits::{ConfigError, ConfigField};
use duolando_core::nn::names::{Role, SchemaError, TensorSpec};
use duolando_core::nn::vq_config::VqConfig;
use duolando_core::tensor::DType;
use proptest::prelude::*;

// ---------------------------------------------------------------- builders

/// The smallest config `ModelConfig::validate` accepts with every stream,
/// part and decoder present (~600 tensors, ~60 KB).
fn tiny_config() -> ModelConfig {
    let vq = |p: Option<Part>| {
        let j = p.map_or(1, |p| p.joints().len() as u32);
        VqConfig {
            in_channels: 3 * j,
            rot_channels: if p.is_some() { 9 * j } else { 0 },
            width: 8,
            depth: 2,
            dilation_growth_rate: 3,
            down_t: 2,
            stride_t: 2,
            emb_width: 8,
            l_bins: 16,
            m_conv_num: 1,
            m_conv_den: 1,
        }
    };
    ModelConfig {
        gpt: GptConfig {
            n_embd: 8,
            n_head: 2,
            n_layer_base: 1,
            n_layer_head: 1,
            block_size: 4,
            look_forward: 2,
            vocab: [16; 5],
            music: LatConfig {
                n_in: 6,
                n_layer: 1,
                n_head: 2,
                downsample_rate: 4,
            },
            leader: LatConfig {
                n_in: 8,
                n_layer: 1,
                n_head: 2,
                downsample_rate: 1,
            },
            n_streams: 10,
            final_ln: false,
        },
        parts: [
            vq(Some(Part::Up)),
            vq(Some(Part::Down)),
            vq(Some(Part::LHand)),
            vq(Some(Part::RHand)),
        ],
        transl: vq(None),
        music_motion_rate: 4,
    }
}

/// Seeded weights for every schema tensor of `cfg` (xorshift, in [-1, 1)).
fn seeded_tensors(cfg: &ModelConfig, seed: u64, store_as: StoreAs) -> Vec<Tensor> {
    let mut state = seed | 1;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 23) as f32 - 1.0
    };
    let mut out = Vec::new();
    for_each_tensor::<SchemaError>(cfg, &mut |spec: &TensorSpec| {
        let n: usize = spec.dims().iter().map(|&d| d as usize).product();
        out.push(Tensor {
            name: spec.name.as_str().to_string(),
            shape: spec.dims().to_vec(),
            values: (0..n).map(|_| next()).collect(),
            store_as,
        });
        Ok(())
    })
    .expect("schema names fit");
    out
}

/// A valid file from the writer (built once, cloned per test case).
fn valid_bytes() -> Vec<u8> {
    static VALID: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    VALID
        .get_or_init(|| {
            let cfg = tiny_config();
            write_duo(&cfg, &seeded_tensors(&cfg, 7, StoreAs::F32))
                .expect("the writer accepts a schema-complete model")
        })
        .clone()
}

/// A valid file taken apart: header (config + entries) and data section.
struct Parts {
    header: Header,
    data: Vec<u8>,
}

fn take_apart(bytes: &[u8]) -> Parts {
    let aligned = AlignedBytes::copy_from(bytes);
    let duo = DuoFile::parse(aligned.as_bytes()).expect("valid input");
    let tensors = duo
        .tensors()
        .map(|e| HeaderEntry {
            name: e.name.to_string(),
            dtype: e.dtype as u8,
            shape: e.dims().to_vec(),
            offset: e.offset,
            nbytes: e.nbytes,
        })
        .collect();
    let data = bytes[duo.prefix().data_start as usize..].to_vec();
    Parts {
        header: Header {
            config: *duo.config().duolando().expect("a Duolando fixture"),
            tensors,
        },
        data,
    }
}

fn valid_parts() -> Parts {
    take_apart(&valid_bytes())
}

fn rebuild(p: &Parts) -> Vec<u8> {
    assemble(&p.header, &p.data).expect("encodes")
}

/// Lays payloads out again in table order (64-aligned), fixing offsets
/// and byte lengths, for mutations that change a payload's size.
fn relayout(header: &mut Header, payloads: &[Vec<u8>]) -> Vec<u8> {
    let mut data = Vec::new();
    for (e, p) in header.tensors.iter_mut().zip(payloads) {
        e.offset = data.len() as u64;
        e.nbytes = p.len() as u64;
        data.extend_from_slice(p);
        data.resize(data.len().next_multiple_of(64), 0);
    }
    data
}

fn payloads(p: &Parts) -> Vec<Vec<u8>> {
    p.header
        .tensors
        .iter()
        .map(|e| p.data[e.offset as usize..(e.offset + e.nbytes) as usize].to_vec())
        .collect()
}

/// Parses from a 64-byte aligned copy.
fn parse(bytes: &[u8]) -> Result<(), FormatError> {
    let aligned = AlignedBytes::copy_from(bytes);
    DuoFile::parse(aligned.as_bytes()).map(|_| ())
}

fn index_of(p: &Parts, pred: impl Fn(&HeaderEntry) -> bool) -> usize {
    p.header
        .tensors
        .iter()
        .position(pred)
        .expect("such a tensor exists in the tiny model")
}

fn set_u32(bytes: &mut [u8], at: usize, v: u32) {
    bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

fn set_u64(bytes: &mut [u8], at: usize, v: u64) {
    bytes[at..at + 8].copy_from_slice(&v.to_le_bytes());
}

// ------------------------------------------------------- the valid baseline

#[test]
fn valid_file_parses_and_round_trips_values() {
    let cfg = tiny_config();
    let tensors = seeded_tensors(&cfg, 7, StoreAs::F32);
    let bytes = write_duo(&cfg, &tensors).unwrap();
    let aligned = AlignedBytes::copy_from(&bytes);
    let duo = DuoFile::parse(aligned.as_bytes()).unwrap();
    assert_eq!(*duo.config(), cfg.into());
    assert_eq!(duo.len(), tensor_count(&cfg));
    assert_eq!(duo.tensors().count(), tensors.len());
    for t in &tensors {
        let view = duo.tensor(&t.name).unwrap();
        assert_eq!(view.dims(), &t.shape[..], "{}", t.name);
        assert_eq!(
            view.data.as_ptr() as usize % 64,
            0,
            "{} payload aligned in memory",
            t.name
        );
        assert_eq!(view.as_f32().unwrap(), &t.values[..], "{}", t.name);
    }
    assert_eq!(
        duo.tensor("gpt.no_such_tensor").unwrap_err(),
        FormatError::NotFound
    );
    assert_eq!(duo.first_non_finite(), None);
}

#[test]
fn valid_f16_file_parses_with_rounded_values() {
    let cfg = tiny_config();
    let tensors = seeded_tensors(&cfg, 11, StoreAs::F16);
    let bytes = write_duo(&cfg, &tensors).unwrap();
    let aligned = AlignedBytes::copy_from(&bytes);
    let duo = DuoFile::parse(aligned.as_bytes()).unwrap();
    let t = &tensors[0];
    let view = duo.tensor(&t.name).unwrap();
    assert_eq!(view.dtype, DType::F16);
    let got: Vec<f32> = view
        .data
        .chunks_exact(2)
        .map(|c| half::f16::from_le_bytes([c[0], c[1]]).to_f32())
        .collect();
    let want: Vec<f32> = t
        .values
        .iter()
        .map(|&v| half::f16::from_f32(v).to_f32())
        .collect();
    assert_eq!(got, want);
}

#[test]
fn committed_fixture_models_open_mapped() {
    for m in ["tiny", "tiny2"] {
        let path = duolando_tests::fixture(&format!("{m}/model.duo"));
        let mf = ModelFile::open(&path).unwrap_or_else(|e| panic!("{e}"));
        assert!(mf.is_mapped());
        let duo = mf.duo().unwrap();
        assert_eq!(duo.len(), duo.config().tensor_count());
    }
}

/// `find` uses a skip index (every `stride`-th entry's offset): every entry
/// must be found at its table index, and no name between, before or after
/// the entries, on files whose counts put names on and off the marks.
#[test]
fn find_locates_every_entry_and_nothing_else() {
    for m in ["tiny", "tiny2"] {
        let mf = ModelFile::open(duolando_tests::fixture(&format!("{m}/model.duo"))).unwrap();
        let duo = mf.duo().unwrap();
        let names: Vec<&str> = duo.tensors().map(|e| e.name).collect();
        assert!(
            names.len() > 64 * 2,
            "{m}: too few tensors to exercise the skip index"
        );
        for (i, n) in names.iter().enumerate() {
            let (at, e) = duo.find(n).unwrap_or_else(|| panic!("{m}: {n} not found"));
            assert_eq!((at as usize, e.name), (i, *n));
            // A name just above this one and below the next is absent.
            assert!(duo.find(&format!("{n}\u{1}")).is_none(), "{m}: {n}+1");
        }
        assert!(duo.find("").is_none());
        assert!(duo.find("\u{1}").is_none());
        assert!(duo.find("\u{10ffff}").is_none());
    }
}

#[test]
fn first_non_finite_finds_a_nan_weight() {
    let mut p = valid_parts();
    let i = 3;
    let at = p.header.tensors[i].offset as usize + 4;
    p.data[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let bytes = rebuild(&p);
    assert_eq!(
        parse(&bytes),
        Err(FormatError::NonFiniteWeight {
            index: i as u32,
            element: 1,
            kind: NonFiniteKind::Nan
        })
    );
    // The table-only parse (for bytes that passed `parse` before) does not
    // read the weights; `first_non_finite` finds it there.
    let aligned = AlignedBytes::copy_from(&bytes);
    let duo =
        DuoFile::parse_without_weight_scan(aligned.as_bytes()).expect("the structure is valid");
    assert_eq!(duo.first_non_finite(), Some((i as u32, 1)));
}

// ------------------------------------------------ one test per rejection

#[test]
fn rejects_misaligned_buffer() {
    let bytes = valid_bytes();
    let mut shifted = vec![0u8];
    shifted.extend_from_slice(&bytes);
    let aligned = AlignedBytes::copy_from(&shifted);
    let err = DuoFile::parse(&aligned.as_bytes()[1..]).unwrap_err();
    assert_eq!(err, FormatError::MisalignedBuffer { addr_mod_64: 1 });
}

#[test]
fn rejects_buffer_shorter_than_prefix() {
    let bytes = valid_bytes();
    assert_eq!(parse(&bytes[..23]), Err(FormatError::TooShort { len: 23 }));
    assert_eq!(parse(&[]), Err(FormatError::TooShort { len: 0 }));
}

#[test]
fn rejects_bad_magic() {
    let mut bytes = valid_bytes();
    bytes[1] = b'X';
    assert!(matches!(parse(&bytes), Err(FormatError::BadMagic { found }) if found[1] == b'X'));
    let msg = parse(&bytes).unwrap_err().to_string();
    let want = format!("0x{:02x}58", bytes[0]);
    assert!(
        msg.contains(&want) && msg.contains("not a .duo file"),
        "{msg}: the magic as 0x-prefixed hex"
    );
}

#[test]
fn rejects_future_version() {
    for v in [0, 3, u32::MAX] {
        let mut bytes = valid_bytes();
        set_u32(&mut bytes, 8, v);
        assert_eq!(
            parse(&bytes),
            Err(FormatError::UnsupportedVersion {
                found: v,
                supported: 2
            })
        );
    }
}

/// Version 1 (a Duolando config first) read as version 2 (a family tag
/// first) is refused, never misread: the config's first varint is not a
/// known family with a config that fits, or the rest does not parse.
#[test]
fn rejects_version_1_header_under_version_2() {
    let mut bytes = valid_bytes();
    set_u32(&mut bytes, 8, 2);
    assert!(parse(&bytes).is_err());
}

/// Version 2: a Duolando model written with its family tag opens as the
/// same model (same config, same tensors); an unknown family tag is
/// refused by number; a Duolando config under the Bailando tag does not
/// pass as a Bailando model.
#[test]
fn version_2_families() {
    use duolando::duo_writer::{assemble_raw_version, write_model_version};
    use duolando_core::family::{Family, FamilyConfig};
    let v1 = valid_bytes();
    let a = AlignedBytes::copy_from(&v1);
    let duo1 = DuoFile::parse(a.as_bytes()).unwrap();
    assert_eq!(duo1.prefix().version, 1);
    let p = valid_parts();
    let cfg = FamilyConfig::Duolando(p.header.config);
    // Re-encode every tensor of the fixture as it is (f32).
    let tensors: Vec<Tensor> = duo1
        .tensors()
        .map(|e| {
            let t = duo1.tensor(e.name).unwrap();
            Tensor {
                name: e.name.to_string(),
                shape: e.dims().to_vec(),
                values: t.as_f32().unwrap().to_vec(),
                store_as: StoreAs::F32,
            }
        })
        .collect();
    let v2 = write_model_version(&cfg, &tensors, 2).unwrap();
    let b = AlignedBytes::copy_from(&v2);
    let duo2 = DuoFile::parse(b.as_bytes()).unwrap();
    assert_eq!(duo2.prefix().version, 2);
    assert_eq!(duo2.config(), duo1.config());
    assert_eq!(duo2.config().family(), Family::Duolando);
    assert_eq!(duo2.len(), duo1.len());
    duolando_core::duolando::model::Model::from_duo(&duo2).unwrap();
    // The header of v2 starts with the tag: patch it.
    for (tag, want_unknown) in [(3u8, true), (127, true), (1, false), (2, false)] {
        let mut bad = v2.clone();
        assert_eq!(bad[24], 0, "Duolando's tag");
        bad[24] = tag;
        let r = parse(&bad);
        if want_unknown {
            assert_eq!(r, Err(FormatError::UnknownFamily { tag: tag as u32 }));
            let msg = r.unwrap_err().to_string();
            assert!(
                msg.contains(&format!("model family {tag}")) && msg.contains("Bailando"),
                "{msg}"
            );
        } else {
            assert!(
                r.is_err(),
                "a Duolando config under another family's tag ({tag}) must not parse: {r:?}"
            );
        }
    }
    // A version-2 header cut inside the tag.
    let bytes = assemble_raw_version(2, &[], &[]).unwrap();
    assert_eq!(
        parse(&bytes),
        Err(FormatError::MalformedHeader {
            field: duolando_core::format::HeaderField::Family,
            offset: 0
        })
    );
}

#[test]
fn rejects_unknown_flags() {
    let mut bytes = valid_bytes();
    set_u32(&mut bytes, 12, 0x10);
    assert_eq!(
        parse(&bytes),
        Err(FormatError::UnknownFlags { flags: 0x10 })
    );
}

#[test]
fn rejects_header_length_over_cap() {
    let mut bytes = valid_bytes();
    set_u64(&mut bytes, 16, MAX_HEADER_LEN + 1);
    assert_eq!(
        parse(&bytes),
        Err(FormatError::HeaderTooLarge {
            header_len: MAX_HEADER_LEN + 1,
            max: MAX_HEADER_LEN
        })
    );
    set_u64(&mut bytes, 16, u64::MAX);
    assert!(matches!(
        parse(&bytes),
        Err(FormatError::HeaderTooLarge { .. })
    ));
}

#[test]
fn rejects_header_length_past_end() {
    let mut bytes = valid_bytes();
    let len = bytes.len() as u64;
    set_u64(&mut bytes, 16, len);
    assert!(
        matches!(parse(&bytes), Err(FormatError::HeaderPastEnd { file_len, .. }) if file_len == len)
    );
}

#[test]
fn rejects_non_zero_padding() {
    let bytes = valid_bytes();
    let header_end = 24 + u64::from_le_bytes(bytes[16..24].try_into().unwrap()) as usize;
    let data_start = header_end.next_multiple_of(64);
    assert!(
        data_start > header_end,
        "the tiny model's header leaves padding"
    );
    let mut bad = bytes.clone();
    bad[data_start - 1] = 1;
    assert_eq!(
        parse(&bad),
        Err(FormatError::NonZeroPadding {
            offset: data_start as u64 - 1
        })
    );
}

#[test]
fn rejects_truncated_config() {
    let p = valid_parts();
    let header = postcard::to_stdvec(&p.header).unwrap();
    let bytes = assemble_raw(&header[..5], &[]).unwrap();
    assert_eq!(
        parse(&bytes),
        Err(FormatError::MalformedHeader {
            field: HeaderField::Config,
            offset: 0
        })
    );
}

#[test]
fn rejects_config_over_the_caps() {
    // An n_embd that would make the arena enormous.
    let mut p = valid_parts();
    p.header.config.gpt.n_embd = 1 << 20;
    assert!(matches!(
        parse(&rebuild(&p)),
        Err(FormatError::InvalidConfig(ConfigError::TooLarge { field: ConfigField::NEmbd, value, .. })) if value == 1 << 20
    ));
    // A layer count over the cap.
    let mut p = valid_parts();
    p.header.config.gpt.n_layer_base = 100_000;
    assert!(matches!(
        parse(&rebuild(&p)),
        Err(FormatError::InvalidConfig(ConfigError::TooLarge {
            field: ConfigField::NLayerBase,
            ..
        }))
    ));
}

#[test]
fn rejects_inconsistent_config() {
    let mut p = valid_parts();
    p.header.config.gpt.n_head = 3; // 8 % 3 != 0
    assert!(matches!(
        parse(&rebuild(&p)),
        Err(FormatError::InvalidConfig(ConfigError::NotDivisible {
            field: ConfigField::NEmbd,
            ..
        }))
    ));
}

#[test]
fn rejects_tensor_count_over_cap() {
    let p = valid_parts();
    let header = postcard::to_stdvec(&(p.header.config, MAX_TENSORS as u64 + 1)).unwrap();
    let bytes = assemble_raw(&header, &[]).unwrap();
    assert_eq!(
        parse(&bytes),
        Err(FormatError::TooManyTensors {
            count: MAX_TENSORS as u64 + 1,
            max: MAX_TENSORS
        })
    );
}

#[test]
fn rejects_table_running_past_header() {
    let p = valid_parts();
    let header = postcard::to_stdvec(&p.header).unwrap();
    let cut = header.len() - 3; // inside the last entry's varints
    let bytes = assemble_raw(&header[..cut], &p.data).unwrap();
    assert!(matches!(
        parse(&bytes),
        Err(FormatError::MalformedHeader {
            field: HeaderField::Offset | HeaderField::ByteLen,
            ..
        })
    ));
}

#[test]
fn rejects_invalid_utf8_name() {
    let p = valid_parts();
    let mut header = postcard::to_stdvec(&p.header).unwrap();
    let first = p.header.tensors[0].name.as_bytes();
    let at = header
        .windows(first.len())
        .position(|w| w == first)
        .unwrap();
    header[at] = 0xFF;
    let bytes = assemble_raw(&header, &p.data).unwrap();
    assert!(matches!(
        parse(&bytes),
        Err(FormatError::MalformedHeader {
            field: HeaderField::Name,
            ..
        })
    ));
}

#[test]
fn rejects_trailing_header_bytes() {
    let p = valid_parts();
    let mut header = postcard::to_stdvec(&p.header).unwrap();
    header.push(0);
    let bytes = assemble_raw(&header, &p.data).unwrap();
    assert_eq!(
        parse(&bytes),
        Err(FormatError::TrailingHeaderBytes { count: 1 })
    );
}

#[test]
fn rejects_empty_name() {
    let mut p = valid_parts();
    p.header.tensors[0].name.clear();
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::EmptyName { index: 0 })
    );
}

#[test]
fn rejects_name_over_cap() {
    let mut p = valid_parts();
    p.header.tensors[0].name = "a".repeat(MAX_NAME_LEN + 1);
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::NameTooLong {
            index: 0,
            len: MAX_NAME_LEN + 1,
            max: MAX_NAME_LEN
        })
    );
}

#[test]
fn rejects_unsorted_table() {
    let mut p = valid_parts();
    let (a, b) = (
        p.header.tensors[0].name.clone(),
        p.header.tensors[1].name.clone(),
    );
    p.header.tensors[0].name = b;
    p.header.tensors[1].name = a;
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::UnsortedTable { index: 1 })
    );
}

#[test]
fn rejects_duplicate_tensor() {
    let mut p = valid_parts();
    p.header.tensors[1].name = p.header.tensors[0].name.clone();
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::DuplicateTensor {
            index: 1,
            previous: 0
        })
    );
}

#[test]
fn rejects_unknown_dtype_code() {
    let mut p = valid_parts();
    p.header.tensors[2].dtype = 7;
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::UnknownDtype { index: 2, code: 7 })
    );
}

#[test]
fn rejects_rank_zero_and_rank_over_cap() {
    let mut p = valid_parts();
    p.header.tensors[2].shape = vec![];
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::BadRank { index: 2, rank: 0 })
    );
    p.header.tensors[2].shape = vec![1; 5];
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::BadRank { index: 2, rank: 5 })
    );
}

#[test]
fn rejects_zero_and_oversized_dims() {
    let mut p = valid_parts();
    p.header.tensors[2].shape = vec![4, 0];
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::DimOutOfRange {
            index: 2,
            axis: 1,
            dim: 0
        })
    );
    p.header.tensors[2].shape = vec![MAX_DIM + 1];
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::DimOutOfRange {
            index: 2,
            axis: 0,
            dim: MAX_DIM + 1
        })
    );
}

#[test]
fn rejects_dims_whose_product_overflows() {
    let mut p = valid_parts();
    p.header.tensors[2].shape = vec![MAX_DIM; 4]; // 2^96 elements
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::SizeOverflow { index: 2 })
    );
}

#[test]
fn rejects_byte_length_not_matching_dtype_and_shape() {
    let mut p = valid_parts();
    let e = &mut p.header.tensors[2];
    let expected = e.nbytes;
    e.nbytes += 4;
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::ByteLenMismatch {
            index: 2,
            expected,
            found: expected + 4
        })
    );
}

#[test]
fn rejects_unaligned_offset() {
    let mut p = valid_parts();
    let last = p.header.tensors.len() - 1;
    p.header.tensors[last].offset += 4;
    let offset = p.header.tensors[last].offset;
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::UnalignedOffset {
            index: last as u32,
            offset
        })
    );
}

#[test]
fn rejects_overlapping_tensors() {
    let mut p = valid_parts();
    p.header.tensors[1].offset = p.header.tensors[0].offset;
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::Overlap {
            index: 1,
            previous: 0
        })
    );
}

#[test]
fn rejects_out_of_range_offset() {
    let mut p = valid_parts();
    let last = p.header.tensors.len() - 1;
    let data_len = p.data.len() as u64;
    p.header.tensors[last].offset = data_len + 64;
    let end = data_len + 64 + p.header.tensors[last].nbytes;
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::DataOutOfRange {
            index: last as u32,
            end,
            data_len
        })
    );
}

#[test]
fn rejects_offset_plus_length_overflow() {
    let mut p = valid_parts();
    let last = p.header.tensors.len() - 1;
    p.header.tensors[last].offset = !63u64; // the largest aligned offset
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::SizeOverflow { index: last as u32 })
    );
}

#[test]
fn rejects_truncated_data() {
    let bytes = valid_bytes();
    let p = take_apart(&bytes);
    let last = p.header.tensors.len() as u32 - 1;
    let cut = &bytes[..bytes.len() - 100];
    assert!(matches!(parse(cut), Err(FormatError::DataOutOfRange { index, .. }) if index == last));
}

/// Asset pipelines pad files: zero bytes after the data section are
/// accepted, in any number; the model is the same.
#[test]
fn accepts_zero_padding_after_the_data() {
    let bytes = valid_bytes();
    for pad in [1usize, 63, 64, 4096 - bytes.len() % 4096, 100_000] {
        let mut padded = bytes.clone();
        padded.resize(bytes.len() + pad, 0);
        let aligned = AlignedBytes::copy_from(&padded);
        let duo =
            DuoFile::parse(aligned.as_bytes()).unwrap_or_else(|e| panic!("{pad} zero bytes: {e}"));
        assert_eq!(duo.len(), duo.config().tensor_count());
        let mf = ModelFile::from_bytes(padded).unwrap_or_else(|e| panic!("{pad} zero bytes: {e}"));
        assert_eq!(mf.bytes().len(), bytes.len() + pad);
    }
}

#[test]
fn rejects_trailing_data() {
    let bytes = valid_bytes();
    // A non-zero byte anywhere after the data section, first or last or
    // after zeros, is named by its file offset.
    for (pad, at) in [(1usize, 0usize), (64, 0), (64, 63), (5000, 4097)] {
        let mut b = bytes.clone();
        b.resize(bytes.len() + pad, 0);
        b[bytes.len() + at] = 0x5a;
        assert_eq!(
            parse(&b),
            Err(FormatError::TrailingData {
                offset: (bytes.len() + at) as u64
            }),
            "pad {pad} at {at}"
        );
    }
    // Another model appended (not zeros): refused at its first byte.
    let mut twice = bytes.clone();
    twice.extend_from_slice(&bytes);
    assert_eq!(
        parse(&twice),
        Err(FormatError::TrailingData {
            offset: bytes.len() as u64
        })
    );
}

#[test]
fn rejects_missing_tensor() {
    let mut p = valid_parts();
    let removed = p.header.tensors.remove(0);
    let err = parse(&rebuild(&p)).unwrap_err();
    let FormatError::MissingTensor { schema_index } = err else {
        panic!("expected MissingTensor, got {err:?}")
    };
    let spec = schema_tensor(&p.header.config.into(), schema_index).unwrap();
    assert_eq!(spec.name.as_str(), removed.name);
}

#[test]
fn rejects_unknown_tensor() {
    let mut p = valid_parts();
    let offset = p.data.len() as u64;
    p.data.extend_from_slice(&[0u8; 64]);
    p.header.tensors.push(HeaderEntry {
        name: "zzz.extra".into(),
        dtype: 0,
        shape: vec![4],
        offset,
        nbytes: 16,
    });
    let index = p.header.tensors.len() as u32 - 1;
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::UnknownTensor { index })
    );
}

#[test]
fn rejects_shape_not_matching_the_config() {
    let mut p = valid_parts();
    let i = index_of(&p, |e| e.shape.len() == 2 && e.shape[0] != e.shape[1]);
    let found = vec![p.header.tensors[i].shape[1], p.header.tensors[i].shape[0]];
    let expected = p.header.tensors[i].shape.clone();
    p.header.tensors[i].shape = found.clone(); // same element count, transposed
    let shape = |d: &[u32]| {
        let mut dims = [1u32; 4];
        dims[..d.len()].copy_from_slice(d);
        Shape {
            rank: d.len() as u8,
            dims,
        }
    };
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::ShapeMismatch {
            index: i as u32,
            expected: shape(&expected),
            found: shape(&found)
        })
    );
}

/// The first ConvTranspose1d weight of the valid file: its index and spec.
fn first_conv_transpose(p: &Parts) -> (usize, TensorSpec) {
    let mut spec = None;
    for_each_tensor::<SchemaError>(&p.header.config, &mut |s: &TensorSpec| {
        if spec.is_none() && s.role == Role::ConvTranspose {
            spec = Some(s.clone());
        }
        Ok(())
    })
    .unwrap();
    let spec = spec.expect("the tiny config has decoders");
    (index_of(p, |e| e.name == spec.name.as_str()), spec)
}

#[test]
fn accepts_conv_transpose_in_gemm_order() {
    let mut p = valid_parts();
    let (i, spec) = first_conv_transpose(&p);
    let [c_in, c_out, k] = spec.dims() else {
        panic!("{spec:?}")
    };
    p.header.tensors[i].shape = vec![c_out * k, *c_in]; // same element count
    assert_eq!(parse(&rebuild(&p)), Ok(()));
}

#[test]
fn rejects_conv_transpose_in_other_rank2_shapes() {
    let mut p = valid_parts();
    let (i, spec) = first_conv_transpose(&p);
    let [c_in, c_out, k] = *spec.dims() else {
        panic!("{spec:?}")
    };
    for found in [
        vec![c_in, c_out * k],
        vec![c_out, k * c_in],
        vec![k * c_in, c_out],
    ] {
        if found == [c_out * k, c_in] {
            continue;
        }
        p.header.tensors[i].shape = found.clone();
        let Err(FormatError::ShapeMismatch {
            index,
            expected,
            found: got,
        }) = parse(&rebuild(&p))
        else {
            panic!("{found:?} accepted")
        };
        assert_eq!(
            (index, expected.rank, &expected.dims[..3], got.rank),
            (i as u32, 3, spec.dims(), 2),
            "{found:?}"
        );
    }
}

/// A model with one tensor re-encoded as Q8Block32 (last dim 32): the
/// `mlp.2` weight `(n_embd, 4*n_embd)` = (8, 32), 8 blocks.
fn with_q8_tensor(scale: half::f16) -> (Vec<u8>, u32) {
    let mut p = valid_parts();
    let mut pay = payloads(&p);
    let i = index_of(&p, |e| e.shape == [8, 32]);
    let mut q = Vec::new();
    for block in 0..8u8 {
        q.extend_from_slice(&scale.to_le_bytes());
        q.extend((0..32u8).map(|v| v.wrapping_mul(block)));
    }
    pay[i] = q;
    p.header.tensors[i].dtype = DType::Q8Block32 as u8;
    let data = relayout(&mut p.header, &pay);
    (assemble(&p.header, &data).unwrap(), i as u32)
}

#[test]
fn accepts_q8_tensor_with_finite_scales() {
    let (bytes, i) = with_q8_tensor(half::f16::from_f32(0.01));
    let aligned = AlignedBytes::copy_from(&bytes);
    let duo = DuoFile::parse(aligned.as_bytes()).unwrap();
    let e = duo.tensors().nth(i as usize).unwrap();
    assert_eq!((e.dtype, e.nbytes), (DType::Q8Block32, 8 * 34));
}

#[test]
fn rejects_nan_or_infinite_quantization_scale() {
    for scale in [half::f16::NAN, half::f16::INFINITY, half::f16::NEG_INFINITY] {
        let (bytes, i) = with_q8_tensor(scale);
        assert_eq!(
            parse(&bytes),
            Err(FormatError::NonFiniteScale { index: i, block: 0 })
        );
    }
}

/// A valid file with the (8, 32) tensor replaced by Q4Block32 blocks whose
/// scale is `scale` in block 5 (and 0.01 elsewhere).
fn with_q4_tensor(scale: half::f16) -> (Vec<u8>, u32) {
    let mut p = valid_parts();
    let mut pay = payloads(&p);
    let i = index_of(&p, |e| e.shape == [8, 32]);
    let mut q = Vec::new();
    for block in 0..8u8 {
        let s = if block == 5 {
            scale
        } else {
            half::f16::from_f32(0.01)
        };
        q.extend_from_slice(&s.to_le_bytes());
        q.extend((0..16u8).map(|v| v.wrapping_mul(block)));
    }
    pay[i] = q;
    p.header.tensors[i].dtype = DType::Q4Block32 as u8;
    let data = relayout(&mut p.header, &pay);
    (assemble(&p.header, &data).unwrap(), i as u32)
}

#[test]
fn accepts_q4_tensor_with_finite_scales() {
    let (bytes, i) = with_q4_tensor(half::f16::from_f32(0.02));
    let aligned = AlignedBytes::copy_from(&bytes);
    let duo = DuoFile::parse(aligned.as_bytes()).unwrap();
    let e = duo.tensors().nth(i as usize).unwrap();
    assert_eq!((e.dtype, e.nbytes), (DType::Q4Block32, 8 * 18));
}

#[test]
fn rejects_nan_or_infinite_q4_scale() {
    for scale in [half::f16::NAN, half::f16::INFINITY, half::f16::NEG_INFINITY] {
        let (bytes, i) = with_q4_tensor(scale);
        assert_eq!(
            parse(&bytes),
            Err(FormatError::NonFiniteScale { index: i, block: 5 })
        );
    }
}

#[test]
fn rejects_q4_payload_of_q8_size() {
    // 8 blocks stored with the Q8 size (34 bytes each) under the Q4 code.
    let (bytes, _) = with_q8_tensor(half::f16::from_f32(0.01));
    let mut p = take_apart(&bytes);
    let i = index_of(&p, |e| e.shape == [8, 32]);
    p.header.tensors[i].dtype = DType::Q4Block32 as u8;
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::ByteLenMismatch {
            index: i as u32,
            expected: 8 * 18,
            found: 8 * 34
        })
    );
}

#[test]
fn rejects_q8_shape_not_in_whole_blocks() {
    let mut p = valid_parts();
    let i = index_of(&p, |e| e.shape == [8, 8]);
    p.header.tensors[i].dtype = DType::Q8Block32 as u8;
    assert_eq!(
        parse(&rebuild(&p)),
        Err(FormatError::SizeOverflow { index: i as u32 })
    );
}

/// A valid file with the (8, 32) tensor re-encoded as `dtype`
/// (Q8Block32x8 or Q4Block32x8: one group; the tiny model has no blocked
/// tensor whose rows need padding: padded groups are covered in
/// tests/int8_layouts.rs) with scale `scale` at row `bad_row` of block 0
/// (0.01 elsewhere).
fn with_x8_tensor(dtype: DType, scale: half::f16, bad_row: usize) -> (Vec<u8>, u32, usize) {
    let mut p = valid_parts();
    let mut pay = payloads(&p);
    let i = index_of(&p, |e| e.shape == [8, 32]);
    let (rows, cols) = (
        p.header.tensors[i].shape[0] as usize,
        p.header.tensors[i].shape[1] as usize,
    );
    let nb = cols / 32;
    let per_block = if dtype == DType::Q4Block32x8 {
        128
    } else {
        256
    };
    let group = nb * (per_block + 16);
    let groups = rows.div_ceil(8);
    let mut q = vec![0u8; groups * group];
    for t in 0..groups {
        let g = &mut q[t * group..(t + 1) * group];
        for (k, v) in g[..nb * per_block].iter_mut().enumerate() {
            *v = (k as u8).wrapping_mul(7);
        }
        for b in 0..nb {
            for n in 0..8 {
                let s = if b == 0 && t * 8 + n == bad_row {
                    scale
                } else {
                    half::f16::from_f32(0.01)
                };
                let at = nb * per_block + 16 * b + 2 * n;
                g[at..at + 2].copy_from_slice(&s.to_le_bytes());
            }
        }
    }
    pay[i] = q;
    p.header.tensors[i].dtype = dtype as u8;
    let data = relayout(&mut p.header, &pay);
    (assemble(&p.header, &data).unwrap(), i as u32, rows)
}

const X8: [(DType, u64); 2] = [(DType::Q8Block32x8, 34), (DType::Q4Block32x8, 18)];

#[test]
fn accepts_x8_tensors_with_finite_scales() {
    for (dtype, block_bytes) in X8 {
        let (bytes, i, rows) = with_x8_tensor(dtype, half::f16::from_f32(0.02), 0);
        let aligned = AlignedBytes::copy_from(&bytes);
        let duo = DuoFile::parse(aligned.as_bytes()).unwrap();
        let e = duo.tensors().nth(i as usize).unwrap();
        let nb = e.shape[1] as u64 / 32;
        assert_eq!(
            (e.dtype, e.nbytes),
            (dtype, rows.div_ceil(8) as u64 * 8 * nb * block_bytes)
        );
    }
}

#[test]
fn rejects_non_finite_x8_scale() {
    for (dtype, _) in X8 {
        for (row, scale) in [
            (0, half::f16::NAN),
            (5, half::f16::INFINITY),
            (7, half::f16::NEG_INFINITY),
        ] {
            let (bytes, i, _) = with_x8_tensor(dtype, scale, row);
            // Blocks numbered group-major, then block, then row: block 0 of
            // row r < 8 of a one-block (8, 32) tensor is r.
            assert_eq!(
                parse(&bytes),
                Err(FormatError::NonFiniteScale {
                    index: i,
                    block: row as u64
                }),
                "{dtype:?} row {row}"
            );
        }
    }
}

#[test]
fn rejects_x8_payload_short_of_its_groups() {
    for (dtype, block_bytes) in X8 {
        let (bytes, _, _) = with_x8_tensor(dtype, half::f16::from_f32(0.01), 0);
        let rows = 7; // one row short of the group
        let mut p = take_apart(&bytes);
        let i = index_of(&p, |e| e.dtype == dtype as u8);
        let nb = p.header.tensors[i].shape[1] as u64 / 32;
        let mut pay = payloads(&p);
        pay[i].truncate(rows * (nb * block_bytes) as usize);
        let data = relayout(&mut p.header, &pay);
        assert_eq!(
            parse(&assemble(&p.header, &data).unwrap()),
            Err(FormatError::ByteLenMismatch {
                index: i as u32,
                expected: 8 * nb * block_bytes,
                found: rows as u64 * nb * block_bytes
            }),
            "{dtype:?}"
        );
    }
}

// ------------------------------------- non-finite f32 / f16 weights (rule 15)

/// A valid file of `store_as` weights with `bits` (one element's little-endian
/// bytes) written at element `element` of table entry `index`.
fn poisoned(store_as: StoreAs, plants: &[(usize, usize, &[u8])]) -> Vec<u8> {
    let cfg = tiny_config();
    let mut bytes = write_duo(&cfg, &seeded_tensors(&cfg, 5, store_as)).unwrap();
    let p = take_apart(&bytes);
    let data_start = bytes.len() - p.data.len();
    for &(index, element, bits) in plants {
        let e = &p.header.tensors[index];
        let at = data_start + e.offset as usize + element * bits.len();
        assert!(
            element * bits.len() < e.nbytes as usize,
            "element {element} inside tensor {index}"
        );
        bytes[at..at + bits.len()].copy_from_slice(bits);
    }
    bytes
}

/// Table entries to poison: the first, the last, and the largest (with
/// elements in its first, a middle and its last block of the scan).
fn poison_sites() -> Vec<(usize, usize)> {
    let p = valid_parts();
    let numel = |e: &HeaderEntry| e.shape.iter().map(|&d| d as usize).product::<usize>();
    let last = p.header.tensors.len() - 1;
    let big = (0..=last)
        .max_by_key(|&i| numel(&p.header.tensors[i]))
        .unwrap();
    let n_big = numel(&p.header.tensors[big]);
    assert!(
        n_big > 600,
        "the largest tiny tensor spans several scan blocks ({n_big} elements)"
    );
    vec![
        (0, 0),
        (last, numel(&p.header.tensors[last]) - 1),
        (big, 0),
        (big, 257),
        (big, n_big / 2 + 1),
        (big, n_big - 1),
    ]
}

#[test]
fn rejects_nan_and_infinite_f32_weights() {
    let cases: [(f32, NonFiniteKind); 4] = [
        (f32::NAN, NonFiniteKind::Nan),
        (f32::from_bits(0xffc0_0001), NonFiniteKind::Nan),
        (f32::INFINITY, NonFiniteKind::PosInf),
        (f32::NEG_INFINITY, NonFiniteKind::NegInf),
    ];
    for (index, element) in poison_sites() {
        for (v, kind) in cases {
            let bytes = poisoned(StoreAs::F32, &[(index, element, &v.to_le_bytes())]);
            assert_eq!(
                parse(&bytes),
                Err(FormatError::NonFiniteWeight {
                    index: index as u32,
                    element: element as u64,
                    kind
                }),
                "f32 {v:?} in tensor {index} element {element}"
            );
        }
    }
    // The largest finite values are weights like any other.
    let bytes = poisoned(
        StoreAs::F32,
        &[
            (0, 0, &f32::MAX.to_le_bytes()),
            (1, 0, &f32::MIN.to_le_bytes()),
        ],
    );
    assert_eq!(parse(&bytes), Ok(()));
}

#[test]
fn rejects_nan_and_infinite_f16_weights() {
    let cases: [(u16, NonFiniteKind); 4] = [
        (0x7e00, NonFiniteKind::Nan),
        (0xfd01, NonFiniteKind::Nan),
        (0x7c00, NonFiniteKind::PosInf),
        (0xfc00, NonFiniteKind::NegInf),
    ];
    let p = take_apart(&poisoned(StoreAs::F16, &[]));
    for (index, element) in poison_sites() {
        assert_eq!(p.header.tensors[index].dtype, DType::F16 as u8);
        for (bits, kind) in cases {
            let bytes = poisoned(StoreAs::F16, &[(index, element, &bits.to_le_bytes())]);
            assert_eq!(
                parse(&bytes),
                Err(FormatError::NonFiniteWeight {
                    index: index as u32,
                    element: element as u64,
                    kind
                }),
                "f16 {bits:#06x} in tensor {index} element {element}"
            );
        }
    }
    // 65504, the largest finite f16.
    assert_eq!(
        parse(&poisoned(StoreAs::F16, &[(0, 0, &0x7bffu16.to_le_bytes())])),
        Ok(())
    );
}

#[test]
fn the_first_non_finite_weight_in_table_order_is_named() {
    let sites = poison_sites();
    let (last, big) = (sites[1], sites[2]);
    let bytes = poisoned(
        StoreAs::F32,
        &[
            (last.0, last.1, &f32::NAN.to_le_bytes()),
            (big.0, 9, &f32::INFINITY.to_le_bytes()),
        ],
    );
    let first = last.0.min(big.0);
    let want = if first == big.0 {
        FormatError::NonFiniteWeight {
            index: big.0 as u32,
            element: 9,
            kind: NonFiniteKind::PosInf,
        }
    } else {
        FormatError::NonFiniteWeight {
            index: last.0 as u32,
            element: last.1 as u64,
            kind: NonFiniteKind::Nan,
        }
    };
    assert_eq!(parse(&bytes), Err(want));
}

#[test]
fn std_message_names_the_non_finite_weight() {
    let sites = poison_sites();
    let (index, element) = sites[4];
    let name = valid_parts().header.tensors[index].name.clone();
    let bytes = poisoned(StoreAs::F16, &[(index, element, &0x7c00u16.to_le_bytes())]);
    let path = std::env::temp_dir().join(format!("duolando-inf-weight-{}.duo", std::process::id()));
    std::fs::write(&path, &bytes).unwrap();
    let err = ModelFile::open(&path).err().expect("rejected at open");
    std::fs::remove_file(&path).ok();
    assert!(matches!(
        err,
        ModelFileError::Format {
            error: FormatError::NonFiniteWeight { .. },
            ..
        }
    ));
    let msg = err.to_string();
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    assert!(
        msg.contains(&format!(
            "tensor #{index} `{name}`: weight element {element} is +inf"
        )),
        "{msg}"
    );
}

// ------------------------------------------------------ std-side messages

#[test]
fn std_message_names_file_tensor_and_shapes() {
    let mut p = valid_parts();
    let i = index_of(&p, |e| e.shape.len() == 2 && e.shape[0] != e.shape[1]);
    let name = p.header.tensors[i].name.clone();
    let s = p.header.tensors[i].shape.clone();
    p.header.tensors[i].shape = vec![s[1], s[0]];
    let err = ModelFile::from_bytes(rebuild(&p)).err().expect("rejected");
    assert!(matches!(
        err,
        ModelFileError::Format {
            error: FormatError::ShapeMismatch { .. },
            ..
        }
    ));
    let msg = err.to_string();
    assert!(msg.contains("<memory>"), "{msg}");
    assert!(msg.contains(&name), "{msg}");
    assert!(
        msg.contains(&format!("[{}, {}]", s[1], s[0]))
            && msg.contains(&format!("[{}, {}]", s[0], s[1])),
        "{msg}"
    );
}

#[test]
fn std_message_names_missing_tensor() {
    let mut p = valid_parts();
    let removed = p.header.tensors.remove(0);
    let msg = ModelFile::from_bytes(rebuild(&p))
        .err()
        .expect("rejected")
        .to_string();
    assert!(msg.contains(&removed.name), "{msg}");
}

#[test]
fn open_names_the_path_of_a_corrupt_file() {
    let mut bytes = valid_bytes();
    bytes[0] = 0;
    let path = std::env::temp_dir().join(format!("duolando-corrupt-{}.duo", std::process::id()));
    std::fs::write(&path, &bytes).unwrap();
    let msg = ModelFile::open(&path).err().expect("rejected").to_string();
    std::fs::remove_file(&path).ok();
    assert!(
        msg.contains(&path.display().to_string()) && msg.contains("magic"),
        "{msg}"
    );
}

// --------------------------------------------------------- never panics

/// One random edit of a valid file.
#[derive(Clone, Debug)]
enum Mutation {
    /// XOR `mask` into the byte at `pos` (mod length).
    Flip { pos: usize, mask: u8 },
    /// Keep only the first `len` bytes (mod length).
    Truncate { len: usize },
    /// Overwrite 8 bytes at `pos` with a little-endian u64 (a length/offset).
    Word { pos: usize, value: u64 },
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        4 => (any::<usize>(), 1u8..=255).prop_map(|(pos, mask)| Mutation::Flip { pos, mask }),
        1 => any::<usize>().prop_map(|len| Mutation::Truncate { len }),
        2 => (any::<usize>(), any::<u64>()).prop_map(|(pos, value)| Mutation::Word { pos, value }),
    ]
}

fn apply(bytes: &mut Vec<u8>, m: &Mutation, header_end: usize) {
    // Bias positions towards the prefix and header, where the structure is.
    let n = bytes.len();
    let pick = |pos: usize| {
        if pos & 3 == 0 {
            pos % n
        } else {
            pos % header_end.clamp(1, n)
        }
    };
    match *m {
        Mutation::Flip { pos, mask } => {
            let at = pick(pos);
            bytes[at] ^= mask;
        }
        Mutation::Truncate { len } => bytes.truncate(len % (n + 1)),
        Mutation::Word { pos, value } => {
            let at = pick(pos).min(n.saturating_sub(8));
            let end = (at + 8).min(n);
            bytes[at..end].copy_from_slice(&value.to_le_bytes()[..end - at]);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn mutated_files_never_panic(muts in proptest::collection::vec(mutation(), 1..6)) {
        let valid = valid_bytes();
        let header_end = 24 + u64::from_le_bytes(valid[16..24].try_into().unwrap()) as usize;
        let mut bytes = valid.clone();
        for m in &muts {
            if bytes.is_empty() { break; }
            apply(&mut bytes, m, header_end);
        }
        let aligned = AlignedBytes::copy_from(&bytes);
        if let Ok(duo) = DuoFile::parse(aligned.as_bytes()) {
            // Whatever passed must be fully usable.
            for e in duo.tensors() {
                let t = duo.tensor(e.name).unwrap();
                prop_assert_eq!(t.data.len() as u64, e.nbytes);
            }
        }
        // The std side must not panic either (message building included).
        let _ = ModelFile::from_bytes(bytes).map_err(|e| e.to_string());
    }

    #[test]
    fn random_bytes_after_a_valid_prefix_never_panic(tail in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let valid = valid_bytes();
        let mut bytes = valid[..24].to_vec();
        bytes.extend_from_slice(&tail);
        let _ = parse(&bytes);
        let _ = ModelFile::from_bytes(bytes).map_err(|e| e.to_string());
    }
}

// ------------------------------------------------- cost of rule 15 at full size

/// A full-size `.duo` (the published config, every tensor `dtype`: f32 or
/// f16), pseudo-random weights in [-0.05, 0.05), 64-byte aligned.
fn full_size_file(dtype: DType) -> AlignedBytes {
    let cfg = duolando_core::duolando::presets::duolando_published();
    let mut specs: Vec<TensorSpec> = Vec::new();
    for_each_tensor::<SchemaError>(&cfg, &mut |s| {
        specs.push(s.clone());
        Ok(())
    })
    .unwrap();
    specs.sort_by(|a, b| a.name.as_str().as_bytes().cmp(b.name.as_str().as_bytes()));
    let width = if dtype == DType::F32 { 4 } else { 2 };
    let mut tensors = Vec::new();
    let mut off = 0u64;
    for s in &specs {
        let numel: u64 = s.dims().iter().map(|&d| d as u64).product();
        tensors.push(HeaderEntry {
            name: s.name.as_str().to_string(),
            dtype: dtype as u8,
            shape: s.dims().to_vec(),
            offset: off,
            nbytes: numel * width,
        });
        off = (off + numel * width).next_multiple_of(64);
    }
    let mut data = vec![0u8; off as usize];
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    for c in data.chunks_exact_mut(4) {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let v = ((state >> 40) as f32 / (1u64 << 23) as f32 - 1.0) * 0.05;
        if width == 4 {
            c.copy_from_slice(&v.to_le_bytes());
        } else {
            let h = half::f16::from_f32(v).to_le_bytes();
            c.copy_from_slice(&[h[0], h[1], h[0], h[1]]);
        }
    }
    let bytes = assemble(
        &Header {
            config: cfg,
            tensors,
        },
        &data,
    )
    .unwrap();
    drop(data);
    AlignedBytes::copy_from(&bytes)
}

fn median_ms(mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..7)
        .map(|_| {
            let s = std::time::Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(|a, b| a.partial_cmp(b).unwrap());
    t[3]
}

/// Rule 15's scan at full size against reading the same bytes (a wrapping
/// u32 sum, one pass) and copying them (memcpy): the figures of
/// docs/FORMAT.md §7. Run: `cargo test --release -p duolando-tests --test
/// corrupt_files -- --ignored --nocapture weight_scan_cost`.
#[test]
#[ignore = "builds 1.8 GB of full-size models; a measurement, run by hand"]
fn weight_scan_cost_at_full_size() {
    for dtype in [DType::F16, DType::F32] {
        let file = full_size_file(dtype);
        let b = file.as_bytes();
        let table = median_ms(|| {
            std::hint::black_box(
                DuoFile::parse_without_weight_scan(std::hint::black_box(b)).unwrap(),
            );
        });
        let full = median_ms(|| {
            std::hint::black_box(DuoFile::parse(std::hint::black_box(b)).unwrap());
        });
        let sum = median_ms(|| {
            let s = std::hint::black_box(b).chunks_exact(4).fold(0u32, |a, c| {
                a.wrapping_add(u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            });
            std::hint::black_box(s);
        });
        let mut dst = vec![0u8; b.len()];
        let copy = median_ms(|| {
            dst.copy_from_slice(std::hint::black_box(b));
            std::hint::black_box(&dst);
        });
        let mb = b.len() as f64 / 1e6;
        let scan = full - table;
        println!(
            "{dtype:?}: {mb:.0} MB; parse {full:.1} ms = table {table:.2} ms + scan {scan:.1} ms ({:.1} GB/s); read (u32 sum) {sum:.1} ms ({:.1} GB/s); memcpy {copy:.1} ms; scan / read {:.2}, scan / memcpy {:.2}",
            mb / scan,
            mb / sum,
            scan / sum,
            scan / copy
        );
    }
}

// ------------------------------------------------------ Transflower (tag 2)

/// The committed Transflower paper model taken apart: its config and
/// entries (a version-2 header) and its data section.
fn transflower_parts() -> (duolando::duo_writer::HeaderV2, Vec<u8>) {
    let bytes = std::fs::read(duolando_tests::fixture("transflower_paper/model.duo")).unwrap();
    let aligned = AlignedBytes::copy_from(&bytes);
    let duo = DuoFile::parse(aligned.as_bytes()).expect("the committed Transflower model parses");
    let tensors = duo
        .tensors()
        .map(|e| HeaderEntry {
            name: e.name.to_string(),
            dtype: e.dtype as u8,
            shape: e.dims().to_vec(),
            offset: e.offset,
            nbytes: e.nbytes,
        })
        .collect();
    (
        duolando::duo_writer::HeaderV2 {
            config: *duo.config(),
            tensors,
        },
        bytes[duo.prefix().data_start as usize..].to_vec(),
    )
}

fn transflower_with(
    edit: &dyn Fn(&mut duolando_core::transflower::config::TransflowerConfig),
) -> Vec<u8> {
    use duolando_core::family::FamilyConfig;
    let (mut h, data) = transflower_parts();
    let FamilyConfig::Transflower(mut cfg) = h.config else {
        panic!("a Transflower fixture")
    };
    edit(&mut cfg);
    h.config = FamilyConfig::Transflower(cfg);
    duolando::duo_writer::assemble_v2(&h, &data).unwrap()
}

/// The committed Transflower model re-assembled unchanged parses (the
/// builders above are faithful), and each config field a corrupt header
/// could carry is checked by `TransflowerConfig::validate`, by name.
#[test]
fn rejects_invalid_transflower_config_fields() {
    use duolando_core::transflower::config::{BaseDist, ConfigError as C, Field, InputConfig};
    let tf = |e| Err(FormatError::InvalidTransflowerConfig(e));
    assert!(parse(&transflower_with(&|_| {})).is_ok());
    assert_eq!(
        parse(&transflower_with(&|c| c.n_inputs = 0)),
        tf(C::Zero {
            field: Field::Inputs
        })
    );
    assert_eq!(
        parse(&transflower_with(&|c| c.n_inputs = 5)),
        tf(C::TooLarge {
            field: Field::Inputs,
            value: 5,
            max: 4
        })
    );
    assert_eq!(
        parse(&transflower_with(&|c| c.nhead = 3)),
        tf(C::NotDivisible {
            field: Field::Dhid,
            value: 16,
            divisor: 3
        })
    );
    assert_eq!(
        parse(&transflower_with(&|c| c.output = 2)),
        tf(C::TooLarge {
            field: Field::Output,
            value: 2,
            max: 1
        })
    );
    assert_eq!(
        parse(&transflower_with(&|c| c.inputs[1].length = 5000)),
        tf(C::TooLarge {
            field: Field::InputLength(1),
            value: 5000,
            max: 4096
        })
    );
    assert_eq!(
        parse(&transflower_with(&|c| c.cond_len = 5)),
        tf(C::Mismatch {
            field: Field::CondLen,
            value: 5,
            expected: 3
        })
    );
    assert_eq!(
        parse(&transflower_with(&|c| c.flow.steps = 33)),
        tf(C::TooLarge {
            field: Field::FlowSteps,
            value: 33,
            max: 32
        })
    );
    assert_eq!(
        parse(&transflower_with(&|c| c.flow.layers = 5)),
        tf(C::TooLarge {
            field: Field::CouplingLayers,
            value: 5,
            max: 4
        })
    );
    assert_eq!(
        parse(&transflower_with(
            &|c| c.flow.base = BaseDist::StudentT { df: 0 }
        )),
        tf(C::Zero {
            field: Field::StudentTDf
        })
    );
    assert_eq!(
        parse(&transflower_with(&|c| c.inputs[1].name = c.inputs[0].name)),
        tf(C::DuplicateName {
            input: 1,
            previous: 0
        })
    );
    assert_eq!(
        parse(&transflower_with(&|c| c.inputs[3] = c.inputs[0])),
        tf(C::UnusedInput { input: 3 })
    );
    assert_eq!(
        parse(&transflower_with(&|c| c.inputs[0] = InputConfig {
            tokens: 4,
            ..c.inputs[0]
        })),
        tf(C::Unsupported(
            duolando_core::transflower::config::Unsupported::WindowType { input: 0 }
        ))
    );
    let msg = parse(&transflower_with(&|c| c.nhead = 3))
        .unwrap_err()
        .to_string();
    assert!(msg.contains("invalid Transflower model config"), "{msg}");
}

/// A modality name is part of every tensor name: a header whose name
/// bytes are not `[A-Za-z0-9_]` (patched in the encoded config) is
/// refused before any name is built.
#[test]
fn rejects_corrupt_transflower_modality_name() {
    use duolando_core::transflower::config::ConfigError as C;
    let bytes = transflower_with(&|_| {});
    let needle = b"expmap_scaled_20";
    let at = bytes
        .windows(needle.len())
        .position(|w| w == needle)
        .expect("the name in the header");
    assert!(
        at < 24 + 400,
        "the first occurrence is the config's, at {at}"
    );
    let mut bad = bytes.clone();
    bad[at + 6] = b'.';
    assert_eq!(
        parse(&bad),
        Err(FormatError::InvalidTransflowerConfig(C::BadName {
            input: 0
        }))
    );
    // A length byte over the 32-byte cap.
    let mut bad = bytes.clone();
    assert_eq!(
        bad[at - 1],
        needle.len() as u8,
        "the length byte before the name"
    );
    bad[at - 1] = 40;
    assert_eq!(
        parse(&bad),
        Err(FormatError::InvalidTransflowerConfig(C::BadName {
            input: 0
        }))
    );
}

/// The config drives the schema: a Transflower config with one flow step
/// fewer than its table holds finds unknown tensors; one more finds a
/// missing tensor; the config cut short does not decode.
#[test]
fn rejects_transflower_table_config_disagreement() {
    match parse(&transflower_with(&|c| c.flow.steps = 2)) {
        Err(FormatError::UnknownTensor { .. }) => {}
        other => panic!("{other:?}"),
    }
    match parse(&transflower_with(&|c| c.flow.steps = 4)) {
        Err(FormatError::MissingTensor { .. }) => {}
        other => panic!("{other:?}"),
    }
    match parse(&transflower_with(&|c| c.pos_emb_output = true)) {
        Err(FormatError::MissingTensor { .. }) => {}
        other => panic!("{other:?}"),
    }
    // Tag 2 followed by a config cut short.
    let bytes = duolando::duo_writer::assemble_raw_version(2, &[2, 2], &[]).unwrap();
    assert_eq!(
        parse(&bytes),
        Err(FormatError::MalformedHeader {
            field: HeaderField::Config,
            offset: 1
        })
    );
}

/// The Transflower file under the other families' tags, and their configs
/// under Transflower's: never read as the wrong family.
#[test]
fn transflower_tag_is_not_interchangeable() {
    let v2 = transflower_with(&|_| {});
    assert_eq!(v2[24], 2, "Transflower's tag");
    for tag in [0u8, 1] {
        let mut bad = v2.clone();
        bad[24] = tag;
        assert!(
            parse(&bad).is_err(),
            "a Transflower config under tag {tag} parsed"
        );
    }
    let btiny = std::fs::read(duolando_tests::fixture("bailando_btiny/model.duo")).unwrap();
    assert_eq!(btiny[24], 1);
    let mut bad = btiny.clone();
    bad[24] = 2;
    assert!(
        parse(&bad).is_err(),
        "a Bailando config under the Transflower tag parsed"
    );
}
