//! The `unsafe` audit of issue #6 item 4 (docs/ROBUSTNESS.md §4), as a
//! test so that it cannot rot:
//!
//! 1. `unsafe` appears only in the files of [`ALLOWED`] (the SIMD kernels
//!    and their tests, the split-GEMM output views of core, the two
//!    read-only file maps, the GEMM thread pool and the ISA switch of
//!    std-adapters, the C ABI and its tests, the counting allocators of
//!    the memory tests); every other crate root forbids or denies it;
//! 2. every `unsafe` block or impl in library code has a `SAFETY:` comment
//!    in the comment block right above it (or on its line);
//! 3. every `unsafe fn` has a `# Safety` doc section or a `SAFETY:` note
//!    in its doc/attribute block;
//! 4. in test code (test files, `#[cfg(test)]` modules), a `SAFETY:`
//!    comment in the enclosing test function before the first unsafe
//!    site covers the function's calls (they share one justification).
//!
//! Run: `cargo test -p duolando-tests --test unsafe_audit`.

use std::fs;
use std::path::{Path, PathBuf};

/// Files that may contain `unsafe`, relative to the workspace root.
const ALLOWED: &[&str] = &[
    "core/src/kernels/simd/mod.rs",
    "core/src/kernels/simd/x86/axpy_rows.rs",
    "core/src/kernels/simd/x86/dot_rows.rs",
    "core/src/kernels/simd/x86/elementwise.rs",
    "core/src/kernels/simd/x86/gemm_q8.rs",
    "core/src/kernels/simd/x86/packed.rs",
    "core/src/kernels/simd/x86/quantise.rs",
    "core/src/kernels/simd/x86/softmax.rs",
    "core/src/kernels/simd/x86/tiles.rs",
    "core/src/kernels/simd/amx.rs",
    "core/src/kernels/simd/tile_pair.rs",
    "core/src/kernels/simd/i8mm.rs",
    "core/src/kernels/simd/matmul.rs",
    "core/src/kernels/simd/neon.rs",
    "core/src/kernels/simd/peak.rs",
    "core/src/kernels/simd/tests.rs",
    "core/src/tests/simd.rs",
    "runtime/src/simd.rs",
    "runtime/src/workers.rs",
    "core/src/kernels/parallel.rs",
    "runtime/src/model_file.rs",
    "std-adapters/src/convert/mod.rs",
    "std-adapters/benches/kernels.rs",
    "ffi/src/lib.rs",
    "ffi/src/model.rs",
    "ffi/src/frames.rs",
    "ffi/src/result.rs",
    "ffi/src/session.rs",
    "ffi/src/batch.rs",
    "ffi/src/batched_session.rs",
    "ffi/src/handle.rs",
    "ffi/src/transflower.rs",
    "ffi/src/transflower_batch.rs",
    "ffi/tests/transflower_batch.rs",
    "ffi/tests/header.rs",
    "ffi/tests/session_golden.rs",
    "ffi/tests/no_alloc.rs",
    "tests/session_memory.rs",
    "tests/bailando_session.rs",
    "ffi/tests/solo_session.rs",
    "ffi/tests/transflower_session.rs",
    "ffi/tests/common/mod.rs",
    "ffi/tests/common/golden.rs",
    "ffi/tests/batched_session.rs",
    "tests/step_many.rs",
    "tests/amx.rs",
    "tests/int8_layouts.rs",
    "tests/linear_fused.rs",
    "tests/attention_isas.rs",
];

/// Crate roots and the lint level they must set for `unsafe_code`.
const ROOTS: &[(&str, &str)] = &[
    ("core/src/lib.rs", "#![deny(unsafe_code)]"),
    ("std-adapters/src/lib.rs", "#![deny(unsafe_code)]"),
    ("runtime/src/lib.rs", "#![deny(unsafe_code)]"),
    ("std-adapters/src/main.rs", "#![forbid(unsafe_code)]"),
    ("gen/src/lib.rs", "#![forbid(unsafe_code)]"),
    ("tests/lib.rs", "#![forbid(unsafe_code)]"),
];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(rd) = fs::read_dir(dir) else { return };
    for e in rd.flatten() {
        let p = e.path();
        let name = e.file_name();
        let name = name.to_string_lossy();
        if p.is_dir() {
            if !matches!(
                name.as_ref(),
                "target" | "fixtures" | "node_modules" | "corpus" | "artifacts"
            ) {
                rust_files(&p, out);
            }
        } else if name.ends_with(".rs") {
            out.push(p);
        }
    }
}

/// The code part of a line (before a `//` comment; string literals holding
/// `//` do not occur on lines with `unsafe` in this code base).
fn code(line: &str) -> &str {
    line.find("//").map_or(line, |i| &line[..i])
}

/// Whether `line`'s code uses the `unsafe` keyword (not `unsafe_code`).
fn has_unsafe(line: &str) -> bool {
    let c = code(line);
    let b = c.as_bytes();
    let mut from = 0;
    while let Some(i) = c[from..].find("unsafe") {
        let at = from + i;
        let before = at.checked_sub(1).map(|j| b[j]);
        let after = b.get(at + 6).copied();
        let word = |x: Option<u8>| x.is_some_and(|x| x.is_ascii_alphanumeric() || x == b'_');
        if !word(before) && !word(after) {
            return true;
        }
        from = at + 6;
    }
    false
}

fn is_comment_or_attr(line: &str) -> bool {
    let t = line.trim_start();
    t.starts_with("//") || t.starts_with("#[") || t.starts_with("#![")
}

/// Site checks of one file; returns "file:line: problem" strings.
fn audit_file(rel: &str, text: &str) -> Vec<String> {
    let lines: Vec<&str> = text.lines().collect();
    let test_file =
        rel.starts_with("tests/") || rel.contains("/tests/") || rel.ends_with("/tests.rs");
    let cfg_test_from = lines
        .iter()
        .position(|l| l.trim_start().starts_with("#[cfg(test)]"))
        .unwrap_or(usize::MAX);
    let mut bad = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        if !has_unsafe(line) {
            continue;
        }
        let c = code(line);
        let is_fn = c.contains("unsafe fn") || c.contains("unsafe extern \"C\" fn");
        let in_test = test_file || i > cfg_test_from;
        // The comment/attribute block right above (and the line itself).
        let mut j = i;
        while j > 0 && is_comment_or_attr(lines[j - 1]) {
            j -= 1;
        }
        let block = lines[j..=i].join("\n");
        // A statement may start a few lines above (`let x = f(\n unsafe {`):
        // look at most 3 code lines up for the block above it.
        let mut k = i;
        for _ in 0..3 {
            if k == 0
                || code(lines[k - 1]).trim_end().ends_with(';')
                || code(lines[k - 1]).trim_end().ends_with('}')
            {
                break;
            }
            k -= 1;
        }
        let mut k0 = k;
        while k0 > 0 && is_comment_or_attr(lines[k0 - 1]) {
            k0 -= 1;
        }
        let stmt_block = lines[k0..=i].join("\n");
        let ok = if is_fn {
            // A fn-pointer type inside a multi-line `type` alias has its
            // `# Safety` section above the alias.
            block.contains("# Safety")
                || block.contains("SAFETY")
                || stmt_block.contains("# Safety")
        } else if in_test {
            // From the enclosing fn (or closure table) line up to the site.
            let start = (0..=i)
                .rev()
                .find(|&m| code(lines[m]).contains("fn "))
                .unwrap_or(0);
            let from = start.saturating_sub(4);
            lines[from..=i].iter().any(|l| l.contains("SAFETY"))
        } else {
            block.contains("SAFETY") || stmt_block.contains("SAFETY")
        };
        if !ok {
            let what = if is_fn {
                "`unsafe fn` without a `# Safety` section"
            } else {
                "`unsafe` without a SAFETY comment"
            };
            bad.push(format!("{rel}:{}: {what}: {}", i + 1, line.trim()));
        }
    }
    bad
}

#[test]
fn unsafe_only_where_allowed_and_always_justified() {
    let root = root();
    let mut files = Vec::new();
    for d in [
        "core",
        "std-adapters",
        "ffi",
        "gen",
        "tests",
        "fuzz/fuzz_targets",
    ] {
        rust_files(&root.join(d), &mut files);
    }
    assert!(
        files.len() > 50,
        "found only {} files under {}",
        files.len(),
        root.display()
    );
    let mut problems = Vec::new();
    let mut sites = 0;
    for p in &files {
        let rel = p
            .strip_prefix(&root)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        let text = fs::read_to_string(p).unwrap();
        let n = text.lines().filter(|l| has_unsafe(l)).count();
        if n == 0 {
            continue;
        }
        sites += n;
        if rel == "tests/unsafe_audit.rs" {
            continue; // its own test strings
        }
        if !ALLOWED.contains(&rel.as_str()) {
            problems.push(format!(
                "{rel}: {n} `unsafe` site(s) in a file outside the allow-list"
            ));
            continue;
        }
        problems.extend(audit_file(&rel, &text));
    }
    assert!(
        problems.is_empty(),
        "{} problem(s) over {sites} unsafe sites:\n{}",
        problems.len(),
        problems.join("\n")
    );
}

#[test]
fn crate_roots_set_their_unsafe_lint() {
    let root = root();
    for (file, attr) in ROOTS {
        let text = fs::read_to_string(root.join(file)).unwrap();
        assert!(
            text.lines().any(|l| l.trim() == *attr),
            "{file} must carry `{attr}`"
        );
    }
}

#[test]
fn the_audit_catches_what_it_claims_to() {
    let unjustified = "fn f() {\n    let x = 1;\n    unsafe { g() };\n}\n";
    assert_eq!(audit_file("core/src/x.rs", unjustified).len(), 1);
    let justified = "fn f() {\n    // SAFETY: g has no preconditions.\n    unsafe { g() };\n}\n";
    assert!(audit_file("core/src/x.rs", justified).is_empty());
    let bare_fn = "/// Adds.\n#[inline]\nunsafe fn h() {}\n";
    assert_eq!(audit_file("core/src/x.rs", bare_fn).len(), 1);
    let doc_fn =
        "/// Adds.\n///\n/// # Safety\n/// The CPU has AVX2.\n#[inline]\nunsafe fn h() {}\n";
    assert!(audit_file("core/src/x.rs", doc_fn).is_empty());
    assert!(!has_unsafe("#![deny(unsafe_code)]"));
    assert!(!has_unsafe("// unsafe { in a comment }"));
    assert!(has_unsafe("let y = unsafe { f() };"));
}
