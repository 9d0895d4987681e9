//! File formats: scenes (INRIA 3DGS PLY, antimatter15's .splat), JSON cameras, posed-image datasets (Blender,
//! nerfstudio, COLMAP), and image outputs (PNG, EXR, NPY), all written atomically (a temporary
//! file in the target's folder, then a rename).

pub mod camera;
pub mod dataset;
pub mod formats;
pub mod image;
mod picture;
pub mod ply;
pub mod undistort;

use std::io::Write;
use std::path::{Path, PathBuf};

/// A text file's contents without the byte-order mark that some Windows editors put first
/// (JSON and COLMAP's formats have none; left in, it reads as part of the first field).
fn without_bom(text: &str) -> &str {
    text.strip_prefix('\u{feff}').unwrap_or(text)
}

/// Writes `path` through a temporary file in the same folder and a rename, so a failed or
/// interrupted write never leaves a partial file behind.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let mut outputs = Outputs::default();
    outputs.stage(path, write)?;
    outputs.commit().map_err(|e| e.error)
}

/// The ending of a file being written (`.scene.ply-Ab12Cd.partial`): renamed to its target
/// when done, removed on failure; left only by a process killed outright.
pub const PARTIAL: &str = ".partial";

/// Files that appear together or not at all (a picture and its depth, a scene and its camera,
/// a dataset's views and transforms): each is written to a temporary file beside its target
/// (in the target's folder, made if missing), and none is moved into place until every one is
/// written. Dropped uncommitted, the staged files are deleted, the folders made for them
/// removed, and the targets left as they were.
#[derive(Default)]
pub struct Outputs {
    staged: Vec<(tempfile::TempPath, PathBuf)>,
    /// The folders `stage` made, outermost first.
    made: Vec<PathBuf>,
}

impl Outputs {
    /// Writes what `write` writes to a temporary file that [`Outputs::commit`] moves to `path`.
    pub fn stage(
        &mut self,
        path: &Path,
        write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
    ) -> std::io::Result<()> {
        self.make_folder(folder_of(path))?;
        // Named for its target, so one that a killed process leaves says what it was.
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        let mut tmp = tempfile::Builder::new()
            .prefix(&format!(".{name}-"))
            .suffix(PARTIAL)
            .tempfile_in(folder_of(path))?;
        {
            let mut buf = std::io::BufWriter::new(tmp.as_file_mut());
            write(&mut buf)?;
            buf.flush()?;
        }
        tmp.as_file().sync_all()?;
        // Temporary files are private (0600); an output should get the usual permissions.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            tmp.as_file()
                .set_permissions(std::fs::Permissions::from_mode(0o644))?;
        }
        // Closed now: a dataset stages hundreds of files.
        self.staged.push((tmp.into_temp_path(), path.to_path_buf()));
        Ok(())
    }

    /// Moves every staged file into place, after checking that none would land on a folder
    /// or on a path another one takes. Only the renames are left by then: one that fails
    /// midway (a target held open on Windows, a folder that forbids replacing another's file)
    /// leaves the targets renamed before it replaced.
    pub fn commit(mut self) -> Result<(), CommitError> {
        let mut targets = std::collections::HashSet::new();
        for (_, path) in &self.staged {
            let refused = |why: &str| CommitError {
                path: path.clone(),
                error: std::io::Error::new(std::io::ErrorKind::InvalidInput, why),
            };
            // A link to a folder would be replaced, not followed.
            if std::fs::symlink_metadata(path).is_ok_and(|m| m.is_dir()) {
                return Err(refused("it is a folder"));
            }
            if !targets.insert(same_file_key(path)) {
                return Err(refused("another output of the same command goes there"));
            }
        }
        // A rename failing midway drops the files not moved yet, and then the folders made
        // for them alone (one holding a moved file is not empty and stays).
        for (tmp, path) in std::mem::take(&mut self.staged) {
            tmp.persist(&path).map_err(|e| CommitError {
                path,
                error: e.error,
            })?;
        }
        self.made.clear();
        Ok(())
    }
}

impl Outputs {
    /// Makes `dir` and its missing parents, remembering which it made.
    fn make_folder(&mut self, dir: &Path) -> std::io::Result<()> {
        let missing: Vec<&Path> = (dir.ancestors())
            .take_while(|d| !d.as_os_str().is_empty() && !d.exists())
            .collect();
        for d in missing.into_iter().rev() {
            match std::fs::create_dir(d) {
                Ok(()) => self.made.push(d.to_path_buf()),
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => {
                    let why = format!("cannot make the folder {}: {e}", d.display());
                    return Err(std::io::Error::new(e.kind(), why));
                }
            }
        }
        Ok(())
    }
}

impl Drop for Outputs {
    /// Uncommitted: the staged files go, then the folders made for them (innermost first;
    /// one that something else has written into since stays).
    fn drop(&mut self) {
        self.staged.clear();
        for d in self.made.iter().rev() {
            let _ = std::fs::remove_dir(d);
        }
    }
}

/// What names one file however the path is spelled (`a.ply`, `./a.ply`, `d/../a.ply`): the
/// canonical folder (it exists: the staged file is in it) and the name.
fn same_file_key(path: &Path) -> (PathBuf, Option<std::ffi::OsString>) {
    let dir = folder_of(path);
    let dir = dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf());
    (dir, path.file_name().map(|n| n.to_os_string()))
}

/// The folder `path` is in (`.` for a bare name).
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// A staged output that could not be put in place.
#[derive(Debug, thiserror::Error)]
#[error("cannot write {}: {error}", path.display())]
pub struct CommitError {
    pub path: PathBuf,
    pub error: std::io::Error,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Folders are made for the staged files and, uncommitted, removed with them: only the
    /// ones made, and only while empty.
    #[test]
    fn folders_made_for_outputs_go_with_them() {
        let dir = tempfile::tempdir().unwrap();
        let at = |p: &str| dir.path().join(p);
        std::fs::create_dir(at("kept")).unwrap();
        let write = |w: &mut dyn Write| w.write_all(b"x");
        let mut outputs = Outputs::default();
        outputs.stage(&at("kept/a/b/one.txt"), write).unwrap();
        outputs.stage(&at("kept/a/two.txt"), write).unwrap();
        outputs.stage(&at("new/c/three.txt"), write).unwrap();
        drop(outputs);
        assert!(at("kept").is_dir());
        for gone in ["kept/a", "new"] {
            assert!(!at(gone).exists(), "{gone} stayed");
        }

        // A refused commit removes them too; one written into meanwhile stays.
        let mut outputs = Outputs::default();
        outputs.stage(&at("new/one.txt"), write).unwrap();
        outputs.stage(&at("other/two.txt"), write).unwrap();
        outputs.stage(&at("other/../other/two.txt"), write).unwrap();
        std::fs::write(at("new/theirs.txt"), b"y").unwrap();
        let err = outputs.commit().unwrap_err().to_string();
        assert!(err.contains("another output"), "{err}");
        assert!(!at("other").exists());
        assert_eq!(std::fs::read_dir(at("new")).unwrap().count(), 1);

        let mut outputs = Outputs::default();
        outputs.stage(&at("made/d/four.txt"), write).unwrap();
        let staged = std::fs::read_dir(at("made/d")).unwrap().next().unwrap();
        let name = staged.unwrap().file_name().into_string().unwrap();
        assert!(
            name.starts_with(".four.txt-") && name.ends_with(PARTIAL),
            "{name}"
        );
        outputs.commit().unwrap();
        assert_eq!(std::fs::read(at("made/d/four.txt")).unwrap(), b"x");
    }

    /// The last ancestor of a relative path (`a/b` -> `a` -> ``) is the working folder,
    /// which is there: nothing to make.
    #[test]
    fn a_relative_paths_last_ancestor_is_not_made() {
        let mut outputs = Outputs::default();
        outputs.make_folder(Path::new("")).unwrap();
        assert!(outputs.made.is_empty());
    }
}
