//! The Python package's test suite (python/tests, pytest), run from `cargo test`: the
//! extension is built into the test venv with maturin (in the dev profile, so it reuses the
//! dependencies this `cargo test` compiled), then pytest runs with `RANK3_BIN` set to this
//! build's binary.
//!
//! The Python is `$RANK3_PYTHON` (else `python3`); it must have maturin, pytest and numpy
//! (`.ci/run` installs them into its venv). Without them the test is skipped with a message.

use std::path::Path;
use std::process::Command;

fn python() -> Option<String> {
    let python = std::env::var("RANK3_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&python)
        .args(["-c", "import maturin, pytest, numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        eprintln!(
            "SKIPPED: `{python}` cannot import maturin, pytest and numpy (pip install maturin \
             pytest numpy, or set RANK3_PYTHON to a venv's Python that has them)"
        );
        return None;
    }
    Some(python)
}

#[test]
fn python_package_test_suite() {
    let Some(python) = python() else { return };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let prefix = Command::new(&python)
        .args(["-c", "import sys; print(sys.prefix)"])
        .output()
        .unwrap();
    let prefix = String::from_utf8_lossy(&prefix.stdout).trim().to_string();
    let build = Command::new(&python)
        .args(["-m", "maturin", "develop", "--quiet"])
        .current_dir(root.join("python"))
        .env("VIRTUAL_ENV", &prefix)
        .output()
        .unwrap();
    assert!(
        build.status.success(),
        "maturin develop failed:\n{}{}",
        String::from_utf8_lossy(&build.stdout),
        String::from_utf8_lossy(&build.stderr)
    );
    let out = Command::new(&python)
        .args([
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "python/tests",
        ])
        .current_dir(root)
        .env("RANK3_BIN", env!("CARGO_BIN_EXE_rank3"))
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    eprintln!("{text}");
    assert!(out.status.success(), "pytest failed:\n{text}");
}
