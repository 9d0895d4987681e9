//! Scenes in every format splat reads and writes, chosen by the file's extension: the INRIA
//! PLY ([`crate::ply`]), PlayCanvas's compressed PLY ([`compressed_ply`], also read from a
//! plain `.ply` name), antimatter15's `.splat` ([`dot_splat`]), Niantic's SPZ ([`spz`]) and
//! PlayCanvas's SOG ([`sog`]).
//! What each keeps and drops: `docs/formats.md`.

pub mod compressed_ply;
pub mod dot_splat;
pub mod morton;
pub mod quantize;
pub mod sog;
pub mod spz;

use crate::ply::{self, GaussianCloud, PlyError};
use std::io::{Read, Write};
use std::path::Path;

/// The file an unbundled SOG is read from (its pictures beside it).
const UNBUNDLED_SOG: &str = "meta.json";

/// Whether `path` names an unbundled SOG's meta.json.
fn is_unbundled_sog(path: &Path) -> bool {
    path.file_name()
        .is_some_and(|n| n.eq_ignore_ascii_case(UNBUNDLED_SOG))
}

/// A scene file's format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// The INRIA 3DGS PLY: every value as f32, SH up to degree 3.
    Ply,
    /// PlayCanvas's compressed PLY: chunks of 256 quantized within their ranges, 16 bytes a
    /// Gaussian and a byte an SH coefficient.
    CompressedPly,
    /// antimatter15's `.splat`: 32 bytes a Gaussian, no SH beyond the DC term.
    Splat,
    /// Niantic's SPZ: about 10x smaller than the PLY, SH kept in 4-5 bits.
    Spz,
    /// PlayCanvas's SOG (bundled): lossless WebP pictures, codebooks and an SH palette.
    Sog,
}

impl Format {
    /// Every format, those whose extension ends another's first.
    pub const ALL: [Format; 5] = [
        Format::CompressedPly,
        Format::Ply,
        Format::Splat,
        Format::Spz,
        Format::Sog,
    ];

    /// The format `path`'s extension names.
    pub fn of(path: &Path) -> Result<Format, SceneError> {
        let name = path
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .to_ascii_lowercase();
        // An unbundled SOG is read from its meta.json.
        if name == UNBUNDLED_SOG {
            return Ok(Format::Sog);
        }
        let found = Format::ALL
            .into_iter()
            .find(|f| name.ends_with(f.extension()));
        found.ok_or_else(|| SceneError::Unknown {
            path: path.display().to_string(),
        })
    }

    pub fn extension(self) -> &'static str {
        match self {
            Format::Ply => ".ply",
            Format::CompressedPly => ".compressed.ply",
            Format::Splat => ".splat",
            Format::Spz => ".spz",
            Format::Sog => ".sog",
        }
    }

    /// Its name on a command line (`splat fit --export`).
    pub fn name(self) -> &'static str {
        match self {
            Format::Ply => "ply",
            Format::CompressedPly => "compressed-ply",
            Format::Splat => "splat",
            Format::Spz => "spz",
            Format::Sog => "sog",
        }
    }

    /// The format named `name` (as [`Format::name`] spells it), or why not.
    pub fn from_name(name: &str) -> Result<Format, String> {
        let found = Format::ALL.into_iter().find(|f| f.name() == name);
        found.ok_or_else(|| {
            let names: Vec<&str> = Format::ALL.iter().map(|f| f.name()).collect();
            format!("no scene format `{name}` (one of {})", names.join(", "))
        })
    }

    /// Whether it says a scene renders antialiased ([`GaussianCloud::antialiased`]).
    pub fn keeps_antialiasing(self) -> bool {
        matches!(self, Format::Spz | Format::CompressedPly | Format::Sog)
    }

    /// The highest SH degree it keeps.
    pub fn most_sh_degree(self) -> u32 {
        match self {
            Format::Ply | Format::CompressedPly | Format::Sog => 3,
            Format::Splat => 0,
            Format::Spz => 3,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error(transparent)]
    Ply(#[from] PlyError),
    #[error("cannot read {path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("{path}: {why}")]
    Format { path: String, why: String },
    #[error(
        "{path}: unknown scene format (the extension names it: .ply, .compressed.ply, .splat, .spz or .sog; an unbundled SOG's meta.json)"
    )]
    Unknown { path: String },
}

/// The scene at `path`, in the format its extension names (a compressed PLY also under a
/// plain `.ply` name: its header tells).
pub fn read(path: &Path) -> Result<GaussianCloud, SceneError> {
    let shown = || path.display().to_string();
    let format = Format::of(path)?;
    if format == Format::Ply && !is_compressed_ply(path) {
        return Ok(ply::read(path)?);
    }
    if is_unbundled_sog(path) {
        return sog::read_folder(path).map_err(|why| SceneError::Format { path: shown(), why });
    }
    let bytes = std::fs::read(path).map_err(|error| SceneError::Io {
        path: shown(),
        error,
    })?;
    // A plain `.ply` name read here holds a compressed PLY.
    let format = match format {
        Format::Ply => Format::CompressedPly,
        other => other,
    };
    parse(format, &bytes).map_err(|why| SceneError::Format { path: shown(), why })
}

/// A whole file's `bytes` in `format` as a cloud; why not, when they are not one.
pub fn parse(format: Format, bytes: &[u8]) -> Result<GaussianCloud, String> {
    match format {
        Format::Ply => ply::parse(&mut &bytes[..]).map_err(|e| e.to_string()),
        Format::CompressedPly => compressed_ply::parse(bytes),
        Format::Spz => spz::parse(bytes),
        Format::Splat => dot_splat::parse(bytes),
        Format::Sog => sog::parse(bytes),
    }
}

/// Whether the PLY file at `path` is a compressed one (false where it cannot be read: the
/// INRIA reader says why).
fn is_compressed_ply(path: &Path) -> bool {
    let mut head = Vec::with_capacity(4096);
    let read = std::fs::File::open(path).and_then(|f| f.take(64 << 10).read_to_end(&mut head));
    read.is_ok() && compressed_ply::is_compressed(&head)
}

/// Writes `cloud` to `path` (atomically) in the format its extension names.
pub fn write(path: &Path, cloud: &GaussianCloud) -> Result<(), SceneError> {
    let format = Format::of(path)?;
    if is_unbundled_sog(path) {
        return Err(SceneError::Format {
            path: path.display().to_string(),
            why: "an unbundled SOG (meta.json and its pictures) is read, not written: write a .sog"
                .into(),
        });
    }
    let written = crate::write_atomic(path, |w| write_to(format, w, cloud));
    written.map_err(|error| SceneError::Io {
        path: path.display().to_string(),
        error,
    })
}

/// Writes `cloud` to `w` in `format`.
pub fn write_to(format: Format, w: &mut dyn Write, cloud: &GaussianCloud) -> std::io::Result<()> {
    match format {
        Format::Ply => ply::write_to(w, cloud),
        Format::CompressedPly => compressed_ply::write_to(w, cloud),
        Format::Splat => dot_splat::write_to(w, cloud),
        Format::Spz => spz::write_to(w, cloud),
        Format::Sog => sog::write_to(w, cloud),
    }
}

/// A random cloud for the formats' tests: `n` Gaussians of SH degree `degree`, each value
/// uniform within ± its range (position, log scale, DC color, the higher SH terms), opacity
/// logits within ±5, rotations within ±1 a component (not normalized).
#[cfg(test)]
pub(crate) fn random_cloud(
    n: usize,
    degree: u32,
    seed: u64,
    [mean, log_scale, dc, rest]: [f32; 4],
) -> GaussianCloud {
    use glam::{Vec3, Vec4};
    let mut rng = fastrand::Rng::with_seed(seed);
    let mut r = |s: f32| (rng.f32() - 0.5) * 2.0 * s;
    let gaussians = (0..n)
        .map(|_| {
            let mut sh = [Vec3::ZERO; 16];
            for (k, c) in sh.iter_mut().take(ply::sh_coefficients(degree)).enumerate() {
                let s = if k == 0 { dc } else { rest };
                *c = Vec3::new(r(s), r(s), r(s));
            }
            crate::ply::StoredGaussian {
                mean: Vec3::new(r(mean), r(mean), r(mean)),
                log_scale: Vec3::new(r(log_scale), r(log_scale), r(log_scale)),
                rotation: Vec4::new(r(1.0), r(1.0), r(1.0), r(1.0)),
                opacity_logit: r(5.0),
                sh,
            }
        })
        .collect();
    GaussianCloud::new(degree, gaussians)
}

/// How far the rotation `read` back is from `stored` (normalized first): the largest component
/// difference, of `read` or of `-read` (q and -q are one rotation), for the formats' tests.
#[cfg(test)]
pub(crate) fn rotation_distance(stored: glam::Vec4, read: glam::Vec4) -> f32 {
    let q = stored.normalize();
    let off = |r: glam::Vec4| (q - r).abs().max_element();
    off(read).min(off(-read))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ply::StoredGaussian;
    use glam::{Vec3, Vec4};

    /// The antialiasing flag survives SPZ, the compressed PLY and SOG, which have a place for
    /// it; the INRIA PLY and `.splat` have none.
    #[test]
    fn the_antialiasing_flag_goes_where_a_format_keeps_it() {
        let g = |k: usize| StoredGaussian {
            mean: Vec3::new(k as f32, 0.5, -1.0),
            log_scale: Vec3::splat(-2.0),
            rotation: Vec4::X,
            opacity_logit: 1.0,
            sh: [Vec3::splat(0.1); 16],
        };
        for antialiased in [false, true] {
            let cloud = GaussianCloud {
                antialiased,
                ..GaussianCloud::new(1, (0..10).map(g).collect())
            };
            for format in Format::ALL {
                let mut bytes = vec![];
                write_to(format, &mut bytes, &cloud).unwrap();
                let kept = format.keeps_antialiasing();
                let read = parse(format, &bytes).unwrap();
                assert_eq!(read.antialiased, antialiased && kept, "{}", format.name());
            }
        }
    }
}
