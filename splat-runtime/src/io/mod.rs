//! File formats: INRIA 3DGS PLY scenes, JSON cameras, posed-image datasets (Blender,
//! nerfstudio, COLMAP), and image outputs (PNG, EXR, NPY), all written atomically (a temporary
//! file in the target's folder, then a rename).

pub mod camera;
pub mod colmap;
pub mod dataset;
pub mod image;
pub mod ply;

use std::io::Write;
use std::path::Path;

/// Writes `path` through a temporary file in the same folder and a rename, so a failed or
/// interrupted write never leaves a partial file behind.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut tmp = tempfile::NamedTempFile::new_in(dir)?;
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
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}
