//! Fuzz targets for every reader of splat: the bytes of one input become the files a reader
//! opens, and the reader must answer (a scene, or an error that says what is wrong): never
//! panic, hang, or allocate far beyond what the input holds. The same targets run under AFL++
//! (`src/bin/afl.rs`, coverage-guided, from the seed corpus in `corpus/TARGET`) and, as CI's
//! smoke run, in `cargo test` (`tests/smoke.rs`: the seeds and deterministic mutations of them).
//!
//! A format of several files (COLMAP's three, Blender's two splits) is one input: the files'
//! bytes joined by [`SEPARATOR`], so the fuzzer mutates each of them and their combinations.
//! The pictures that datasets name are small valid PNGs written once into the scratch folder
//! (`a.png`, `b.png`, also under `images/`): they are inputs of another reader (the `image`
//! crate's), not of ours.

use splat_runtime::Image;
use splat_runtime::glam::Vec3;
use splat_runtime::io::dataset::{self, colmap};
use splat_runtime::io::{camera, formats, image, ply};
use std::path::{Path, PathBuf};

/// Joins the files of a multi-file input.
pub const SEPARATOR: &[u8] = b"\n%%splat-fuzz-next-file%%\n";

/// A reader under test.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// An INRIA 3DGS PLY scene.
    Ply,
    /// antimatter15's `.splat` scene.
    Splat,
    /// Niantic's SPZ scene (every version: gzip or per-attribute zstd streams).
    Spz,
    /// PlayCanvas's compressed PLY scene.
    CompressedPly,
    /// PlayCanvas's SOG scene (a ZIP of WebP pictures and meta.json).
    Sog,
    /// A camera JSON file.
    Camera,
    /// A COLMAP sparse model, binary: `cameras.bin`, `images.bin`, `points3D.bin`.
    ColmapBinary,
    /// A COLMAP sparse model, text: `cameras.txt`, `images.txt`, `points3D.txt`.
    ColmapText,
    /// A Blender / NeRF-synthetic dataset: `transforms_train.json`, `transforms_test.json`.
    Blender,
    /// A nerfstudio dataset: `transforms.json`.
    Nerfstudio,
}

impl Target {
    pub const ALL: [Target; 10] = [
        Target::Ply,
        Target::Splat,
        Target::Spz,
        Target::CompressedPly,
        Target::Sog,
        Target::Camera,
        Target::ColmapBinary,
        Target::ColmapText,
        Target::Blender,
        Target::Nerfstudio,
    ];

    /// Its name on the command line and its corpus folder's.
    pub fn name(self) -> &'static str {
        match self {
            Target::Ply => "ply",
            Target::Splat => "splat",
            Target::Spz => "spz",
            Target::CompressedPly => "compressed_ply",
            Target::Sog => "sog",
            Target::Camera => "camera",
            Target::ColmapBinary => "colmap_binary",
            Target::ColmapText => "colmap_text",
            Target::Blender => "blender",
            Target::Nerfstudio => "nerfstudio",
        }
    }

    pub fn from_name(name: &str) -> Option<Target> {
        Target::ALL.into_iter().find(|t| t.name() == name)
    }

    /// The seed corpus of this target in the repository.
    pub fn corpus(self) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("corpus")
            .join(self.name())
    }

    /// The bytes its reader may hold at once per byte of input. A compressed format's scene
    /// is rightly larger than its file: SPZ unpacks to at most 1024 times its size (Niantic's
    /// bound), 20 bytes or more a Gaussian of 236 bytes in memory, so 1024 (its streams) plus
    /// 1024 / 20 x 236 (its Gaussians) = 13,108 a byte. SOG claims at most 64 Gaussians a
    /// byte, each 7 RGBA pixels (28 bytes) decoded and 236 in memory: 16,896. The other
    /// readers hold a bounded multiple of what the file holds (a JSON number of two bytes
    /// becomes a 32-byte value).
    pub fn most_per_byte(self) -> usize {
        match self {
            Target::Spz => 13_108,
            Target::Sog => formats::sog::MOST_PER_BYTE * (7 * 4 + 236),
            _ => 64,
        }
    }

    /// Reads `bytes` as this target's files; whether the reader accepts them is its business,
    /// only a panic (or a hang, or a huge allocation) is a finding. Returns whether it accepted.
    pub fn run(self, scratch: &Scratch, bytes: &[u8]) -> bool {
        let dir = scratch.dir.as_path();
        let background = Vec3::ZERO;
        match self {
            Target::Ply => ply::parse(&mut &bytes[..]).is_ok(),
            Target::Splat => formats::dot_splat::parse(bytes).is_ok(),
            Target::Spz => formats::spz::parse(bytes).is_ok(),
            Target::CompressedPly => formats::compressed_ply::parse(bytes).is_ok(),
            Target::Sog => formats::sog::parse(bytes).is_ok(),
            Target::Camera => {
                let path = dir.join("camera.json");
                write(&path, bytes);
                camera::read(&path).is_ok()
            }
            Target::ColmapBinary | Target::ColmapText => {
                let ext = match self {
                    Target::ColmapBinary => "bin",
                    _ => "txt",
                };
                let sparse = dir.join("sparse/0");
                let files = ["cameras", "images", "points3D"];
                for (stem, part) in files.iter().zip(parts(bytes, files.len())) {
                    write(&sparse.join(format!("{stem}.{ext}")), part);
                }
                // Only this format's files: the other's would be read instead.
                let other = if ext == "bin" { "txt" } else { "bin" };
                for stem in files {
                    let _ = std::fs::remove_file(sparse.join(format!("{stem}.{other}")));
                }
                colmap::read_colmap(dir, background, None).is_ok()
            }
            Target::Blender => {
                let splits = ["transforms_train.json", "transforms_test.json"];
                for (name, part) in splits.iter().zip(parts(bytes, splits.len())) {
                    write(&dir.join(name), part);
                }
                dataset::read_blender(dir, background).is_ok()
            }
            Target::Nerfstudio => {
                write(&dir.join("transforms.json"), bytes);
                dataset::read_nerfstudio(dir, background).is_ok()
            }
        }
    }
}

/// `bytes` cut at [`SEPARATOR`] into `n` files (the last takes the rest; missing ones empty).
pub fn parts(bytes: &[u8], n: usize) -> Vec<&[u8]> {
    let mut out = Vec::with_capacity(n);
    let mut rest = bytes;
    while out.len() + 1 < n {
        match find(rest, SEPARATOR) {
            Some(at) => {
                out.push(&rest[..at]);
                rest = &rest[at + SEPARATOR.len()..];
            }
            None => break,
        }
    }
    out.push(rest);
    out.resize(n, &[]);
    out
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

fn write(path: &Path, bytes: &[u8]) {
    std::fs::write(path, bytes)
        .unwrap_or_else(|e| panic!("cannot write the input {}: {e}", path.display()));
}

/// The folder a target's files are written to, with the pictures datasets name; removed when
/// dropped.
pub struct Scratch {
    dir: PathBuf,
}

impl Scratch {
    pub fn new() -> std::io::Result<Scratch> {
        static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let k = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("splat-fuzz-{}-{k}", std::process::id()));
        std::fs::create_dir_all(dir.join("sparse/0"))?;
        std::fs::create_dir_all(dir.join("images"))?;
        let picture = Image {
            width: 4,
            height: 3,
            channels: 4,
            data: (0..48).map(|i| (i % 5) as f32 / 4.0).collect(),
        };
        for name in ["a.png", "b.png", "images/a.png", "images/b.png"] {
            image::write_image(&dir.join(name), &picture).map_err(std::io::Error::other)?;
        }
        Ok(Scratch { dir })
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
