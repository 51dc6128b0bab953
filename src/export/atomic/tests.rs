//! The checked writer on real files: links, modes, leftovers, inputs.

use super::*;
use anyhow::Result;
use std::io::Write;
use std::os::unix::fs::PermissionsExt;
use std::path::Path;

fn write(path: &Path, text: &str) -> Result<()> {
    let mut f = AtomicFile::create(path)?;
    f.writer().write_all(text.as_bytes())?;
    f.commit()
}

/// The process umask (Linux: /proc/self/status), which a new file's mode must respect.
fn umask() -> u32 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("Umask:")).unwrap();
    u32::from_str_radix(line["Umask:".len()..].trim(), 8).unwrap()
}

#[test]
fn links_modes_and_leftovers() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // a symlink stays a link; its target gets the content
    std::fs::write(d.join("real.json"), "old").unwrap();
    std::os::unix::fs::symlink("real.json", d.join("link.json")).unwrap();
    write(&d.join("link.json"), "new").unwrap();
    assert!(std::fs::symlink_metadata(d.join("link.json"))
        .unwrap()
        .file_type()
        .is_symlink());
    assert_eq!(std::fs::read_to_string(d.join("real.json")).unwrap(), "new");
    // hard links all see the new content
    std::fs::hard_link(d.join("real.json"), d.join("hard.json")).unwrap();
    write(&d.join("real.json"), "newer").unwrap();
    assert_eq!(
        std::fs::read_to_string(d.join("hard.json")).unwrap(),
        "newer"
    );
    // an existing file keeps its mode
    std::fs::write(d.join("m.csv"), "x").unwrap();
    std::fs::set_permissions(d.join("m.csv"), std::fs::Permissions::from_mode(0o640)).unwrap();
    write(&d.join("m.csv"), "y").unwrap();
    let mode = std::fs::metadata(d.join("m.csv"))
        .unwrap()
        .permissions()
        .mode();
    assert_eq!(mode & 0o777, 0o640);
    // a new file is 0666 less the umask (not 0600 whatever the umask)
    write(&d.join("new.csv"), "z").unwrap();
    let mode = std::fs::metadata(d.join("new.csv"))
        .unwrap()
        .permissions()
        .mode()
        & 0o777;
    assert_eq!(mode, 0o666 & !umask(), "mode {mode:o}");
    // a stale temporary of a dead process is swept; one of ours and foreign names are not
    let stale = d.join(".fibrefit-999999999-0123456789ab.tmp");
    let foreign = d.join(".fibrefit-notours.tmp");
    std::fs::write(&stale, "").unwrap();
    std::fs::write(&foreign, "").unwrap();
    write(&d.join("other.json"), "w").unwrap();
    assert!(!stale.exists());
    assert!(foreign.exists());
    // dropped without commit: nothing left, target untouched
    {
        let mut f = AtomicFile::create(&d.join("m.csv")).unwrap();
        f.writer().write_all(b"half").unwrap();
    }
    assert_eq!(std::fs::read_to_string(d.join("m.csv")).unwrap(), "y");
    let left: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .flatten()
        .filter(|e| {
            let n = e.file_name();
            let n = n.to_string_lossy();
            n.starts_with(".fibrefit-") && n != ".fibrefit-notours.tmp"
        })
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn an_input_is_never_an_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("data.csv"), "x").unwrap();
    std::os::unix::fs::symlink("data.csv", d.join("alias.csv")).unwrap();
    std::fs::hard_link(d.join("data.csv"), d.join("hard.csv")).unwrap();
    let inputs = vec![d.join("data.csv")];
    for out in ["data.csv", "alias.csv", "hard.csv", "./data.csv"] {
        let e = Outputs::new(&inputs)
            .file(&d.join(out), "--out")
            .err()
            .unwrap();
        assert!(e.to_string().contains("is an input"), "{e}");
    }
    Outputs::new(&inputs)
        .file(&d.join("result.json"), "--out")
        .unwrap();
}
