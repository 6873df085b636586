//! The documents a user reads follow the program (issue 53): every `sheen`
//! command the README, the user guide (`docs/`) and BENCHMARKS.md show in a
//! shell block still parses with today's command line.

use std::path::{Path, PathBuf};

use clap::Parser as _;

/// The shell words of one command line: quotes and backslashes as a shell
/// reads them; `None` where the line does more than run one command
/// (pipes, redirections, substitutions, background jobs).
fn shell_words(line: &str) -> Option<Vec<String>> {
    let mut words = Vec::new();
    let mut word = String::new();
    let mut in_word = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '\'' => {
                in_word = true;
                for q in chars.by_ref() {
                    if q == '\'' {
                        break;
                    }
                    word.push(q);
                }
            }
            '"' => {
                in_word = true;
                while let Some(q) = chars.next() {
                    match q {
                        '"' => break,
                        '\\' => word.extend(chars.next()),
                        '$' | '`' => return None,
                        _ => word.push(q),
                    }
                }
            }
            '\\' => {
                in_word = true;
                word.extend(chars.next());
            }
            '#' if !in_word => break,
            '|' | '>' | '<' | '&' | ';' | '$' | '`' => return None,
            c if c.is_whitespace() => {
                if in_word {
                    words.push(std::mem::take(&mut word));
                    in_word = false;
                }
            }
            c => {
                in_word = true;
                word.push(c);
            }
        }
    }
    if in_word {
        words.push(word);
    }
    Some(words)
}

/// Every `sheen` command in the shell blocks of `text`, as its words after
/// `sheen` (environment assignments and `cargo run --release --` taken off).
fn sheen_commands(text: &str) -> Vec<(usize, Vec<String>)> {
    let mut commands = Vec::new();
    let mut in_shell = false;
    let mut pending: Option<(usize, String)> = None;
    for (n, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if let Some(lang) = trimmed.strip_prefix("```") {
            in_shell = !in_shell && matches!(lang.trim(), "sh" | "bash" | "shell" | "console");
            continue;
        }
        if !in_shell {
            continue;
        }
        let (start, joined) = match pending.take() {
            Some((start, before)) => (start, format!("{before} {trimmed}")),
            None => (n + 1, trimmed.to_string()),
        };
        if let Some(rest) = joined.strip_suffix('\\') {
            pending = Some((start, rest.to_string()));
            continue;
        }
        let Some(words) = shell_words(&joined) else { continue };
        let mut words: &[String] = &words;
        while words.first().is_some_and(|w| w.contains('=') && !w.starts_with('-')) {
            words = &words[1..];
        }
        let rest = match words {
            [first, rest @ ..] if first == "sheen" => rest,
            [c, r, release, dashes, rest @ ..]
                if c == "cargo" && r == "run" && release == "--release" && dashes == "--" =>
            {
                rest
            }
            _ => continue,
        };
        commands.push((start, rest.to_vec()));
    }
    commands
}

fn documents() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = vec![root.join("README.md"), root.join("BENCHMARKS.md")];
    let mut guide: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .expect("docs/")
        .filter_map(Result::ok)
        .map(|e| e.path())
        // The history records commands as they were run then.
        .filter(|p| p.extension().is_some_and(|e| e == "md") && !p.ends_with("benchmarks-history.md"))
        .collect();
    guide.sort();
    files.extend(guide);
    files
}

#[test]
fn the_reader_finds_commands_as_a_shell_would() {
    let text = "```sh\n# a comment\nSHEEN_SIMD=avx2 sheen analyze a.json --out 'q c' \\\n  --flatness \"base<=15\" # why\n\
                sheen history | head\ncargo run --release -- check x.json\n```\nsheen not-in-a-block\n";
    let found = sheen_commands(text);
    let expected: Vec<(usize, Vec<String>)> = vec![
        (3, ["analyze", "a.json", "--out", "q c", "--flatness", "base<=15"].map(String::from).to_vec()),
        (6, ["check", "x.json"].map(String::from).to_vec()),
    ];
    assert_eq!(found, expected);
}

#[test]
fn every_command_the_documents_show_still_parses() {
    let mut checked = 0;
    let mut failures = Vec::new();
    for file in documents() {
        let text = std::fs::read_to_string(&file).expect("read");
        for (line, args) in sheen_commands(&text) {
            checked += 1;
            let argv = std::iter::once("sheen".to_string()).chain(args.iter().cloned());
            if let Err(e) = sheen::cli::Cli::try_parse_from(argv) {
                let first = e.to_string().lines().next().unwrap_or_default().to_string();
                failures.push(format!("{}:{line}: sheen {}\n    {first}", file.display(), args.join(" ")));
            }
        }
    }
    assert!(checked >= 30, "only {checked} commands found: the reader has lost them");
    assert!(failures.is_empty(), "commands the documents show that no longer parse:\n{}", failures.join("\n"));
}
