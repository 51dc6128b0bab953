//! The README leads: its first lines are the two commands, it stays a front page, and every
//! relative link in it and in docs/ points at a file of the repository.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn markdown_files() -> Vec<PathBuf> {
    let mut v = vec![root().join("README.md"), root().join("ARCHITECTURE.md")];
    let mut stack = vec![root().join("docs")];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "md") {
                v.push(p);
            }
        }
    }
    v
}

/// Relative link targets `](target)` (anchors dropped), skipping URLs.
fn links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        if let Some(j) = rest.find(')') {
            let t = rest[..j].split('#').next().unwrap_or("");
            if !t.is_empty() && !t.contains("://") && !t.contains(' ') {
                out.push(t.to_string());
            }
        }
    }
    out
}

#[test]
fn the_readme_opens_with_the_two_commands() {
    let text = std::fs::read_to_string(root().join("README.md")).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "# fibrefit");
    assert_eq!(lines[2], "```sh");
    assert!(lines[3].starts_with("cargo run --release -- fit data_synthetic/"));
    assert_eq!(
        lines[4], "scripts/test.sh",
        "the test command sets itself up"
    );
    let script = std::fs::read_to_string(root().join("scripts/test.sh")).unwrap();
    for step in ["apt-get install", "cargo test", "pytest"] {
        assert!(script.contains(step), "scripts/test.sh lacks `{step}`");
    }
    let ci = std::fs::read_to_string(root().join(".ci/run")).unwrap();
    assert!(
        ci.contains("scripts/test.sh"),
        ".ci/run runs the README's test command"
    );
    assert_eq!(lines[5], "```");
    // the main job's data and config are shipped
    for word in lines[3].split_whitespace() {
        if word.starts_with("data_synthetic/") || word.starts_with("configs/") {
            assert!(
                root().join(word).is_file(),
                "{word} is not in the repository"
            );
        }
    }
    assert!(
        lines.len() <= 250,
        "the README is a front page: {} lines",
        lines.len()
    );
}

#[test]
fn every_relative_link_in_the_docs_resolves() {
    let files = markdown_files();
    assert!(files.len() >= 10, "docs/ holds the guide: {files:?}");
    let mut bad = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        for t in links(&text) {
            let target = f.parent().unwrap_or(Path::new(".")).join(&t);
            if !target.exists() {
                bad.push(format!("{}: {t}", f.display()));
            }
        }
    }
    assert!(bad.is_empty(), "links to nothing: {bad:#?}");
}

#[test]
fn the_model_contract_lives_in_the_repository() {
    let text = std::fs::read_to_string(root().join("docs/MODEL.md")).unwrap();
    for section in [
        "## 1. Frames",
        "## 2. The fibre geometry",
        "## 5. Parameters",
        "The seeds",
    ] {
        assert!(text.contains(section), "docs/MODEL.md lacks {section}");
    }
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    assert!(
        !readme.contains("../shared/MODEL.md"),
        "the README points outside the repository"
    );
    assert!(
        readme.contains("**rung**"),
        "the README explains `rung` where it first uses it"
    );
}

#[test]
fn the_fit_guide_stays_a_users_guide() {
    let text = std::fs::read_to_string(root().join("docs/guide/fit.md")).unwrap();
    let n = text.lines().count();
    assert!(
        n <= 250,
        "docs/guide/fit.md is a user's guide of at most 250 lines (measurements belong in \
         docs/figures.md, the config's keys in docs/formats.md): {n} lines"
    );
}
