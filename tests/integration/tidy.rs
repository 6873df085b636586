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
