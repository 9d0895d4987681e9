//! `splat new NAME`: a crate for a new method that builds and passes its checks at once: a 3D
//! Gaussian whose falloff is the author's to change (`templates/lib.rs`), the whole command
//! line (`templates/main.rs`), every check in one call and a short training run
//! (`templates/checks.rs`), splat by path with splat's own lockfile, and splat's target folder
//! so the first build reuses what splat compiled.

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};

/// The crate's files: (path inside the crate, template). The manifest's template is
/// `Cargo.toml.in`: cargo leaves a folder holding a `Cargo.toml` out of splat-cli's package.
const FILES: [(&str, &str); 7] = [
    ("Cargo.toml", include_str!("../templates/Cargo.toml.in")),
    (
        ".cargo/config.toml",
        include_str!("../templates/config.toml"),
    ),
    (".gitignore", include_str!("../templates/gitignore")),
    ("README.md", include_str!("../templates/README.md")),
    ("src/lib.rs", include_str!("../templates/lib.rs")),
    ("src/main.rs", include_str!("../templates/main.rs")),
    ("tests/checks.rs", include_str!("../templates/checks.rs")),
];

/// Where this binary was built from, if that is still a splat checkout.
fn own_checkout() -> Option<PathBuf> {
    let cli = Path::new(env!("CARGO_MANIFEST_DIR"));
    let root = cli.parent()?.parent()?;
    is_checkout(root).then(|| root.to_path_buf())
}

fn is_checkout(dir: &Path) -> bool {
    dir.join("splat-macros/Cargo.toml").is_file() && dir.join("splat-runtime/Cargo.toml").is_file()
}

/// Writes the crate `name` into `dir` (default `./name`), depending on the splat checkout
/// `splat` (default: the one this binary was built from). Nothing is written unless all of
/// it is: the files go to a temporary folder beside `dir`, renamed into place at the end.
pub fn new_crate(name: &str, dir: Option<&Path>, splat: Option<&Path>) -> Result<PathBuf> {
    let module = module_name(name)?;
    let dir = dir.map_or_else(|| PathBuf::from(name), Path::to_path_buf);
    if dir.exists() {
        bail!("`{}` already exists: choose another --dir", dir.display());
    }
    let splat = match splat {
        Some(s) if is_checkout(s) => s.to_path_buf(),
        Some(s) => bail!(
            "--splat `{}` is not a splat checkout (no splat-macros/ and splat-runtime/ there)",
            s.display()
        ),
        None => own_checkout().context(
            "this binary was not built from a splat checkout that still exists: give one \
             with --splat PATH",
        )?,
    };
    let splat = splat
        .canonicalize()
        .with_context(|| format!("reading {}", splat.display()))?;
    let Some(splat_text) = splat.to_str().filter(|s| !s.contains(['"', '\\'])) else {
        bail!(
            "the splat checkout's path `{}` cannot be written into Cargo.toml",
            splat.display()
        );
    };
    let parent = match dir.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).with_context(|| format!("creating {}", parent.display()))?;
    let staging = tempfile::Builder::new()
        .prefix(".splat-new-")
        .tempdir_in(&parent)
        .with_context(|| format!("writing into {}", parent.display()))?;
    let fill = |template: &str| {
        template
            .replace("{{name}}", name)
            .replace("{{module}}", &module)
            .replace("{{crate}}", &name.replace('-', "_"))
            .replace("{{splat}}", splat_text)
    };
    for (path, template) in FILES {
        let to = staging.path().join(path);
        if let Some(folder) = to.parent() {
            std::fs::create_dir_all(folder)?;
        }
        std::fs::write(&to, fill(template)).with_context(|| format!("writing {path}"))?;
    }
    // splat's lockfile: the dependency versions splat was tested with.
    let lock = splat.join("Cargo.lock");
    if lock.is_file() {
        std::fs::copy(&lock, staging.path().join("Cargo.lock")).context("copying Cargo.lock")?;
    }
    let staged = staging.keep();
    if let Err(e) = std::fs::rename(&staged, &dir) {
        std::fs::remove_dir_all(&staged).ok();
        return Err(e).with_context(|| format!("creating {}", dir.display()));
    }
    Ok(dir)
}

/// The method's module: `name` with `-` as `_`, which must then be a Rust identifier (and a
/// crate name cargo takes: ASCII letters, digits, `-` and `_`, starting with a letter).
fn module_name(name: &str) -> Result<String> {
    let valid = name.chars().next().is_some_and(|c| c.is_ascii_lowercase())
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-' || c == '_');
    if !valid {
        bail!(
            "`{name}` cannot name a crate and its method: use lowercase ASCII letters, digits, \
             `-` and `_`, starting with a letter (e.g. `student-splats`)"
        );
    }
    let module = name.replace('-', "_");
    // Names the generated code or Rust itself already takes.
    const TAKEN: [&str; 8] = [
        "self",
        "super",
        "crate",
        "mod",
        "fn",
        "struct",
        "splat_runtime",
        "blocks",
    ];
    if TAKEN.contains(&module.as_str()) {
        bail!("`{name}` is taken by Rust or splat: choose another name");
    }
    Ok(module)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_must_make_a_crate_and_a_module() {
        assert_eq!(module_name("student-splats").unwrap(), "student_splats");
        for bad in ["", "Student", "1st", "a b", "naïve", "crate", "x/y"] {
            assert!(module_name(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn every_placeholder_is_filled() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("my-splat");
        let root = own_checkout().expect("tests run in a checkout");
        new_crate("my-splat", Some(&out), Some(&root)).unwrap();
        for (path, _) in FILES {
            let text = std::fs::read_to_string(out.join(path)).unwrap();
            assert!(!text.contains("{{"), "{path}: {text}");
        }
        let lib = std::fs::read_to_string(out.join("src/lib.rs")).unwrap();
        assert!(lib.contains("pub mod my_splat {"), "{lib}");
        assert!(out.join("Cargo.lock").is_file());
        let err = new_crate("my-splat", Some(&out), Some(&root)).unwrap_err();
        assert!(err.to_string().contains("already exists"), "{err}");
        // Nothing is left beside it.
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().flatten().collect();
        assert_eq!(names.len(), 1);
    }
}
