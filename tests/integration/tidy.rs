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
