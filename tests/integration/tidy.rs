//! Source-tree rules that keep the architecture honest (rust-analyzer's
//! `tidy.rs`): the computing modules never import GUI crates, and every
//! source file says what it is for.

use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

#[test]
fn computing_modules_do_not_import_gui_crates() {
    let forbidden = ["egui", "eframe", "wgpu", "rfd", "crate::app", "winit"];
    let mut offenders = Vec::new();
    for module in ["engine", "analysis", "io", "records", "sim", "cli"] {
        let mut files = Vec::new();
        rust_files(&src().join(module), &mut files);
        for file in files {
            let text = std::fs::read_to_string(&file).unwrap_or_default();
            for (n, line) in text.lines().enumerate() {
                let code = line.split("//").next().unwrap_or("");
                for f in forbidden {
                    let uses = code.contains(&format!("{f}::")) || code.contains(&format!("use {f}"));
                    // The CLI starts the app as its no-subcommand case, and only that.
                    let allowed = module == "cli" && f == "crate::app" && code.contains("crate::app::run(");
                    if uses && !allowed {
                        offenders.push(format!("{}:{}: {}", file.display(), n + 1, line.trim()));
                    }
                }
            }
        }
    }
    assert!(offenders.is_empty(), "GUI imports outside src/app:\n{}", offenders.join("\n"));
}

/// A view draws its own state and the shared runtime; what two views share
/// lives in `views/mod.rs` or beside the views in `src/app`, so a view can
/// change without another breaking.
#[test]
fn views_do_not_import_each_other() {
    let views_dir = src().join("app").join("views");
    let views: Vec<String> = std::fs::read_dir(&views_dir)
        .expect("src/app/views")
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let stem = name.strip_suffix(".rs").unwrap_or(&name).to_string();
            (stem != "mod").then_some(stem)
        })
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    assert!(views.contains(&"history".to_string()) && views.contains(&"inspect".to_string()), "{views:?}");
    let mut offenders = Vec::new();
    for view in &views {
        let mut files = Vec::new();
        let (file, folder) = (views_dir.join(format!("{view}.rs")), views_dir.join(view));
        if file.is_file() {
            files.push(file);
        }
        rust_files(&folder, &mut files);
        for file in files {
            let text = std::fs::read_to_string(&file).unwrap_or_default();
            for (n, line) in text.lines().enumerate() {
                let code = line.split("//").next().unwrap_or("");
                for other in views.iter().filter(|o| *o != view) {
                    let paths = [format!("views::{other}::"), format!("views::{other};"), format!("super::{other}::")];
                    // A view's own submodules reach their parent's siblings only through `super::super`.
                    let nested = file.parent() == Some(folder.as_path()) && code.contains(&format!("super::{other}::"));
                    if paths.iter().any(|p| code.contains(p.as_str())) && !nested {
                        offenders.push(format!("{}:{}: {}", file.display(), n + 1, line.trim()));
                    }
                }
            }
        }
    }
    assert!(offenders.is_empty(), "views importing other views:\n{}", offenders.join("\n"));
}

#[test]
fn engine_does_no_file_io() {
    let mut files = Vec::new();
    rust_files(&src().join("engine"), &mut files);
    let mut offenders = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap_or_default();
        for (n, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            if ["std::fs", "File::", "crate::io", "crate::sim"].iter().any(|p| code.contains(p)) {
                offenders.push(format!("{}:{}: {}", file.display(), n + 1, line.trim()));
            }
        }
    }
    assert!(offenders.is_empty(), "the engine must not do I/O or use sim:\n{}", offenders.join("\n"));
}

#[test]
fn every_source_file_starts_with_module_docs() {
    let mut files = Vec::new();
    rust_files(&src(), &mut files);
    rust_files(&Path::new(env!("CARGO_MANIFEST_DIR")).join("tests"), &mut files);
    let missing: Vec<String> = files
        .iter()
        .filter(|f| !std::fs::read_to_string(f).unwrap_or_default().trim_start().starts_with("//!"))
        .map(|f| f.display().to_string())
        .collect();
    assert!(missing.is_empty(), "files without a `//!` header:\n{}", missing.join("\n"));
}

/// What a platform-specific path needs from the `cfg` gate around it:
/// `libc` is a dependency only for Linux with glibc (Cargo.toml), the Unix
/// and Windows extension modules exist only there.
fn gate_allows(path: &str, predicate: &str) -> bool {
    let predicate = predicate.replace(' ', "");
    if predicate.starts_with("not(") {
        return false;
    }
    let linux_gnu = predicate.contains("target_os=\"linux\"") && predicate.contains("target_env=\"gnu\"");
    match path {
        "libc::" => linux_gnu,
        "std::os::unix" | "std::os::fd" => {
            predicate.contains("unix")
                || ["linux", "macos", "freebsd", "android"]
                    .iter()
                    .any(|os| predicate.contains(&format!("target_os=\"{os}\"")))
        }
        "std::os::linux" => predicate.contains("target_os=\"linux\""),
        "std::os::windows" => predicate.contains("windows"),
        _ => false,
    }
}

const PLATFORM_PATHS: [&str; 5] = ["libc::", "std::os::unix", "std::os::fd", "std::os::linux", "std::os::windows"];

/// Uses of [`PLATFORM_PATHS`] in `source` that no `#[cfg(...)]` gate allows,
/// as (line, path). A gate covers the item or statement it is written on:
/// the braces it opens, or up to the `;` or `,` that ends it. Comments,
/// strings and character literals are skipped.
fn ungated_platform_uses(source: &str) -> Vec<(usize, &'static str)> {
    fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
        hay.windows(needle.len()).position(|w| w == needle)
    }
    fn lines_in(bytes: &[u8]) -> usize {
        bytes.iter().filter(|&&b| b == b'\n').count()
    }
    let bytes = source.as_bytes();
    let (mut i, mut line) = (0usize, 1usize);
    // One entry per open bracket: the gate it opened, if any.
    let mut stack: Vec<Option<String>> = Vec::new();
    // A gate read but not yet attached: its predicate and the depth it was written at.
    let mut pending: Option<(String, usize)> = None;
    let mut found = Vec::new();
    while i < bytes.len() {
        let rest = &bytes[i..];
        let c = bytes[i];
        if c == b'\n' {
            line += 1;
            i += 1;
        } else if rest.starts_with(b"//") {
            i += find(rest, b"\n").unwrap_or(rest.len());
        } else if rest.starts_with(b"/*") {
            let end = find(rest, b"*/").map_or(rest.len(), |e| e + 2);
            line += lines_in(&rest[..end]);
            i += end;
        } else if (rest.starts_with(b"r#\"") || rest.starts_with(b"r\""))
            && (i == 0 || !(bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_'))
        {
            let hashes = rest[1..].iter().take_while(|&&h| h == b'#').count();
            let mut close = vec![b'"'];
            close.extend(std::iter::repeat_n(b'#', hashes));
            let body = 2 + hashes;
            let end = find(&rest[body..], &close).map_or(rest.len(), |e| body + e + close.len());
            line += lines_in(&rest[..end]);
            i += end;
        } else if c == b'"' {
            let mut j = i + 1;
            while j < bytes.len() && bytes[j] != b'"' {
                if bytes[j] == b'\\' {
                    j += 1;
                }
                if j < bytes.len() && bytes[j] == b'\n' {
                    line += 1;
                }
                j += 1;
            }
            i = j + 1;
        } else if c == b'\'' && bytes.get(i + 1) == Some(&b'\\') {
            i += find(&rest[2..], b"'").map_or(rest.len(), |e| e + 3);
        } else if c == b'\'' && bytes.get(i + 2) == Some(&b'\'') {
            i += 3;
        } else if rest.starts_with(b"#[cfg(") {
            let end = find(rest, b")]").map_or(rest.len(), |e| e + 2);
            let predicate = String::from_utf8_lossy(&rest[b"#[cfg(".len()..end.saturating_sub(2)]).into_owned();
            pending = Some((predicate, stack.len()));
            line += lines_in(&rest[..end]);
            i += end;
        } else if let Some(path) = PLATFORM_PATHS.iter().find(|p| rest.starts_with(p.as_bytes())) {
            let preceded = i > 0 && (bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_');
            let allowed = stack.iter().flatten().any(|g| gate_allows(path, g))
                || pending.as_ref().is_some_and(|(g, _)| gate_allows(path, g));
            if !preceded && !allowed {
                found.push((line, *path));
            }
            i += path.len();
        } else {
            match c {
                b'{' | b'(' | b'[' => {
                    let gate = match &pending {
                        Some((g, depth)) if *depth == stack.len() && c == b'{' => Some(g.clone()),
                        _ => None,
                    };
                    if gate.is_some() {
                        pending = None;
                    }
                    stack.push(gate);
                }
                b'}' | b')' | b']' => {
                    stack.pop();
                    if pending.as_ref().is_some_and(|(_, depth)| *depth > stack.len()) {
                        pending = None;
                    }
                }
                b';' | b',' if pending.as_ref().is_some_and(|(_, depth)| *depth == stack.len()) => pending = None,
                _ => {}
            }
            i += 1;
        }
    }
    found
}

/// The scanner itself: it finds what is ungated and passes what is gated.
#[test]
fn the_platform_scanner_tells_gated_from_ungated_uses() {
    let ungated = "fn f() -> i32 { libc::EINVAL }\nfn g() { use std::os::unix::fs::PermissionsExt; }";
    assert_eq!(ungated_platform_uses(ungated), vec![(1, "libc::"), (2, "std::os::unix")]);
    let gated = r#"
#[cfg(all(target_os = "linux", target_env = "gnu"))]
mod linux_gnu { pub fn f() -> i32 { libc::EINVAL } }
fn g() {
    #[cfg(unix)]
    let mode = std::os::unix::fs::PermissionsExt::mode(&p); // libc:: in a comment
    let s = "libc::EINVAL in a string";
    #[cfg(unix)]
    { use std::os::unix::fs::MetadataExt as _; }
}"#;
    assert_eq!(ungated_platform_uses(gated), vec![]);
    // libc under a gate that admits musl, whose build has no libc dependency.
    let musl = "#[cfg(target_os = \"linux\")]\nfn f() -> i32 { libc::EINVAL }";
    assert_eq!(ungated_platform_uses(musl), vec![(2, "libc::")]);
    // A gate ends with its statement.
    let ended = "fn g() {\n    #[cfg(unix)]\n    let a = 1;\n    use std::os::unix::fs::FileExt;\n}";
    assert_eq!(ungated_platform_uses(ended), vec![(4, "std::os::unix")]);
    let negated = "#[cfg(not(unix))]\nfn f() { use std::os::unix::fs::FileExt; }";
    assert_eq!(ungated_platform_uses(negated), vec![(2, "std::os::unix")]);
}

/// Every platform call sits in an item gated to the platforms that have it
/// (issue 53): this machine cannot build for macOS or Windows, so this test
/// stands in for those builds.
#[test]
fn platform_calls_sit_in_gated_items() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for dir in ["src", "tests", "benches", "examples"] {
        rust_files(&root.join(dir), &mut files);
    }
    let mut offenders = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap_or_default();
        for (line, path) in ungated_platform_uses(&text) {
            offenders.push(format!("{}:{line}: {path}", file.strip_prefix(root).unwrap_or(&file).display()));
        }
    }
    assert!(offenders.is_empty(), "platform calls outside a matching #[cfg] gate:\n{}", offenders.join("\n"));
}

/// BENCHMARKS.md opens with one table of the current figures (issue 53):
/// every row says what it times, the figure, the target, the date, the
/// commit and the machine; a commit named is one in the history (where the
/// checkout has its history: a shallow clone skips that part).
#[test]
fn benchmarks_open_with_one_current_table() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("BENCHMARKS.md")).expect("BENCHMARKS.md");
    let current = text.find("## Current figures").expect("a 'Current figures' section");
    assert!(
        text[..current].lines().filter(|l| l.starts_with("## ")).count() == 0,
        "the current figures come first, before any other section"
    );
    let header = "| what it times | figure | target | date | commit | machine |";
    let table: Vec<&str> =
        text[current..].lines().skip_while(|l| *l != header).skip(2).take_while(|l| l.starts_with('|')).collect();
    assert!(table.len() >= 5, "the current table has the headline rows: {table:?}");
    let git = |args: &[&str]| std::process::Command::new("git").args(args).current_dir(root).output().ok();
    let has_history = git(&["rev-parse", "--is-shallow-repository"])
        .is_some_and(|o| o.status.success() && String::from_utf8_lossy(&o.stdout).trim() == "false");
    for row in table {
        let cells: Vec<&str> = row.trim_matches('|').split('|').map(str::trim).collect();
        assert_eq!(cells.len(), 6, "six cells: {row}");
        let [what, figure, _target, date, commit, machine] = cells[..] else { unreachable!() };
        assert!(!what.is_empty() && !figure.is_empty() && !machine.is_empty(), "{row}");
        let date_ok = date.len() == 10
            && date.chars().enumerate().all(|(i, c)| if i == 4 || i == 7 { c == '-' } else { c.is_ascii_digit() });
        assert!(date_ok, "a date YYYY-MM-DD: {row}");
        assert!(commit.len() >= 7 && commit.chars().all(|c| c.is_ascii_hexdigit()), "a commit: {row}");
        if has_history {
            let known = git(&["cat-file", "-e", &format!("{commit}^{{commit}}")]).is_some_and(|o| o.status.success());
            assert!(known, "commit {commit} is in the history: {row}");
        }
    }
}
