//! include/duolando.h is hand-written: check it against the Rust side.
//! - the functions it declares = the `extern "C"` functions of ffi/src
//!   (.ci/ffi.sh checks the same list against `nm` on the built libraries);
//! - the C# wrapper (integrations/unity/Runtime/Duolando.cs) binds only declared
//!   functions;
//! - the result codes and struct sizes it states match the Rust types.

use std::collections::BTreeSet;
use std::path::Path;

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// `text` with C comments removed.
fn strip_c_comments(text: &str) -> String {
    let mut out = String::new();
    let mut rest = text;
    while let Some(i) = rest.find("/*") {
        out.push_str(&rest[..i]);
        match rest[i..].find("*/") {
            Some(j) => rest = &rest[i + j + 2..],
            None => {
                rest = "";
            }
        }
    }
    out.push_str(rest);
    out.lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

fn ident_at(s: &str) -> &str {
    let end = s
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .unwrap_or(s.len());
    &s[..end]
}

/// Names `duo_*` directly followed by `(` (function declarations).
pub fn header_functions(header: &str) -> BTreeSet<String> {
    let code = strip_c_comments(header);
    let mut names = BTreeSet::new();
    let mut rest = code.as_str();
    while let Some(i) = rest.find("duo_") {
        let before_ok = i == 0
            || !rest.as_bytes()[i - 1].is_ascii_alphanumeric() && rest.as_bytes()[i - 1] != b'_';
        let name = ident_at(&rest[i..]);
        let after = rest[i + name.len()..].trim_start();
        if before_ok && after.starts_with('(') {
            names.insert(name.to_string());
        }
        rest = &rest[i + name.len().max(1)..];
    }
    names
}

/// `extern "C" fn duo_*` in the Rust sources, plus `value_fn!` invocations.
fn rust_exports() -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    for entry in std::fs::read_dir(root().join("ffi/src")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "rs") {
            let text = std::fs::read_to_string(&path).unwrap();
            let mut lines = text.lines().peekable();
            while let Some(line) = lines.next() {
                let t = line.trim_start();
                if let Some(i) = t.find("extern \"C\" fn duo_") {
                    names.insert(ident_at(&t[i + "extern \"C\" fn ".len()..]).to_string());
                }
                if t.starts_with("value_fn!(") {
                    // The name is the first line after the doc comments.
                    for l in lines.by_ref() {
                        let l = l.trim_start();
                        if l.starts_with("duo_") {
                            names.insert(ident_at(l).to_string());
                            break;
                        }
                    }
                }
            }
        }
    }
    names
}

#[test]
fn header_declares_exactly_the_exported_functions() {
    let header = std::fs::read_to_string(root().join("include/duolando.h")).unwrap();
    let declared = header_functions(&header);
    let exported = rust_exports();
    assert!(declared.len() >= 10, "{declared:?}");
    let missing: Vec<_> = exported.difference(&declared).collect();
    let stale: Vec<_> = declared.difference(&exported).collect();
    assert!(
        missing.is_empty() && stale.is_empty(),
        "exported but not in the header: {missing:?}; declared but not exported: {stale:?}"
    );
}

#[test]
fn csharp_wrapper_binds_declared_functions_only() {
    let path = root().join("integrations/unity/Runtime/Duolando.cs");
    // A moved wrapper must fail here, not skip the check.
    let cs = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let header = std::fs::read_to_string(root().join("include/duolando.h")).unwrap();
    let declared = header_functions(&header);
    let mut bound = BTreeSet::new();
    for line in cs.lines() {
        let t = line.trim_start();
        if t.contains("static extern ") {
            if let Some(i) = t.find(" duo_") {
                bound.insert(ident_at(&t[i + 1..]).to_string());
            }
        }
    }
    assert!(!bound.is_empty());
    let unknown: Vec<_> = bound.difference(&declared).collect();
    assert!(
        unknown.is_empty(),
        "Duolando.cs binds functions the header does not declare: {unknown:?}"
    );
}

#[test]
fn header_result_codes_match() {
    // SAFETY: every C entry point below is called with NULL (where the test checks NULL handling) or with pointers to live locals of the documented sizes; handles come from the library and are freed once.
    let header = std::fs::read_to_string(root().join("include/duolando.h")).unwrap();
    let code = strip_c_comments(&header);
    for (i, name) in [
        "DUO_OK",
        "DUO_NULL_PARAMETER",
        "DUO_INVALID_ARGUMENT",
        "DUO_BAD_MODEL",
        "DUO_BUFFER_TOO_SMALL",
        "DUO_NOT_READY",
        "DUO_NON_FINITE_INPUT",
        "DUO_BACKLOG",
        "DUO_IO",
        "DUO_PANIC",
        "DUO_INTERNAL",
    ]
    .iter()
    .enumerate()
    {
        assert!(
            code.contains(&format!("{name} = {i}")),
            "{name} = {i} not in the header"
        );
        let s = unsafe { std::ffi::CStr::from_ptr(duolando::result::duo_result_name(i as i32)) };
        assert_eq!(s.to_str().unwrap(), *name);
    }
}

/// The family codes of the header are the core's `Family` discriminants.
#[test]
fn header_family_codes_match() {
    let h = std::fs::read_to_string(root().join("include/duolando.h")).unwrap();
    for f in duolando_core::family::Family::ALL {
        let line = format!(
            "#define DUO_FAMILY_{} {}u",
            f.name().to_uppercase(),
            f as u32
        );
        assert!(h.contains(&line), "missing `{line}` in include/duolando.h");
    }
}

/// The per-family joint counts of the header are the core's.
#[test]
fn header_joint_counts_match() {
    let h = std::fs::read_to_string(root().join("include/duolando.h")).unwrap();
    assert!(h.contains(&format!(
        "#define DUO_JOINTS {}\n",
        duolando_core::family::Family::Duolando.joints()
    )));
    assert!(h.contains(&format!(
        "#define DUO_BAILANDO_JOINTS {}\n",
        duolando_core::family::Family::Bailando.joints()
    )));
}
