//! The INRIA 3D Gaussian Splatting PLY format: binary little endian, one `vertex` element
//! with float properties `x y z [nx ny nz] f_dc_0..2 f_rest_0..(3(K-1)-1) opacity scale_0..2
//! rot_0..3`, `f_rest` channel-major (all R coefficients, then G, then B). The SH degree
//! (0 to 3) is read from the number of `f_rest` properties.
//!
//! A Mip-Splatting file adds `filter_3D`, the standard deviation of its 3D smoothing
//! filter. It is folded in at reading, as Mip-Splatting's own fused export does: the
//! filter convolved with the Gaussian adds filter² to each squared scale, and the opacity
//! is scaled by the ratio of the determinants so that the Gaussian's integral is unchanged.
//!
//! ```
//! use splat_io::ply::{self, GaussianCloud, StoredGaussian};
//! use glam::{Vec3, Vec4};
//!
//! let gaussian = StoredGaussian {
//!     mean: Vec3::new(0.0, 0.0, 4.0),
//!     log_scale: Vec3::splat(-1.5),
//!     rotation: Vec4::new(1.0, 0.0, 0.0, 0.0),
//!     opacity_logit: 2.0,
//!     sh: std::array::from_fn(|i| Vec3::splat(i as f32 / 16.0)),
//! };
//! let cloud = GaussianCloud::new(3, vec![gaussian]);
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("scene.ply");
//! ply::write(&path, &cloud)?; // through a temporary file and a rename
//! assert_eq!(ply::read(&path)?, cloud);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use glam::{Vec3, Vec4};
use std::collections::HashMap;
use std::io::{BufRead, Read, Write};
use std::path::Path;

/// One Gaussian as stored: raw (pre-activation) values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StoredGaussian {
    pub mean: Vec3,
    /// ln of the scales.
    pub log_scale: Vec3,
    /// Quaternion (w, x, y, z), not necessarily normalized.
    pub rotation: Vec4,
    /// Opacity before the sigmoid.
    pub opacity_logit: f32,
    /// SH coefficients by basis function (16 for degree 3; unused ones are zero).
    pub sh: [Vec3; 16],
}

#[derive(Clone, Debug, PartialEq)]
pub struct GaussianCloud {
    pub sh_degree: u32,
    pub gaussians: Vec<StoredGaussian>,
    /// Whether the file held Mip-Splatting's 3D filter, now folded into the Gaussians.
    pub folded_3d_filter: bool,
    /// Whether it was trained antialiased (Mip-Splatting's 2D filter, `--method 3dgs-aa`), as
    /// SPZ's flag 0x1, the compressed PLY's `SplatRenderMode: mip` and SOG's `"model":
    /// "antialiased"` say; the INRIA PLY has no place for it.
    pub antialiased: bool,
}

#[derive(Debug, thiserror::Error)]
pub enum PlyError {
    #[error("cannot read {path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("{path}: {error}")]
    In { path: String, error: Box<PlyError> },
    #[error("not a PLY file (it must start with `ply`)")]
    NotPly,
    #[error("unsupported PLY format `{0}`: only binary_little_endian 1.0 is supported")]
    Format(String),
    #[error("malformed PLY header: {0}")]
    Header(String),
    #[error("missing property `{0}` in the vertex element")]
    Missing(String),
    #[error("{0} f_rest properties do not match an SH degree (0, 9, 24 or 45 expected)")]
    ShCount(usize),
    #[error("truncated PLY: expected {expected} vertices, the file holds data for {found}")]
    Truncated { expected: usize, found: usize },
    #[error("vertex {index}: property `{property}` is {value} (NaN or infinite)")]
    NonFinite {
        index: usize,
        property: String,
        value: f32,
    },
}

/// Number of SH coefficients per channel for a degree.
pub fn sh_coefficients(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}

#[derive(Clone, Copy)]
enum Kind {
    F32,
    F64,
    U8,
}

impl Kind {
    fn parse(s: &str) -> Option<Kind> {
        match s {
            "float" | "float32" => Some(Kind::F32),
            "double" | "float64" => Some(Kind::F64),
            "uchar" | "uint8" => Some(Kind::U8),
            _ => None,
        }
    }
    fn size(self) -> usize {
        match self {
            Kind::F32 => 4,
            Kind::F64 => 8,
            Kind::U8 => 1,
        }
    }
}

pub fn read(path: &Path) -> Result<GaussianCloud, PlyError> {
    let io = |error| PlyError::Io {
        path: path.display().to_string(),
        error,
    };
    if path.is_dir() {
        return Err(io(std::io::Error::other("it is a folder")));
    }
    let file = std::fs::File::open(path).map_err(io)?;
    parse(&mut std::io::BufReader::new(file)).map_err(|error| PlyError::In {
        path: path.display().to_string(),
        error: Box::new(error),
    })
}

/// The longest header line read: a stream without line breaks (`/dev/zero`) is not read
/// whole in search of one.
const MAX_HEADER_LINE: u64 = 16 << 20;

/// Parses a PLY stream (header, then the vertex data; anything after the vertices is not
/// read).
pub fn parse(r: &mut impl BufRead) -> Result<GaussianCloud, PlyError> {
    let mut line = String::new();
    let mut next_line = |r: &mut dyn BufRead| -> Result<String, PlyError> {
        line.clear();
        let n = (Read::take(&mut *r, MAX_HEADER_LINE))
            .read_line(&mut line)
            .map_err(|e| PlyError::Header(e.to_string()))?;
        if n == 0 {
            return Err(PlyError::Header(
                "the header ends before `end_header`".into(),
            ));
        }
        if n as u64 == MAX_HEADER_LINE && !line.ends_with('\n') {
            return Err(PlyError::Header(format!(
                "a header line runs past {} MiB",
                MAX_HEADER_LINE >> 20
            )));
        }
        Ok(line.trim_end().to_string())
    };
    if next_line(r).map_err(|_| PlyError::NotPly)? != "ply" {
        return Err(PlyError::NotPly);
    }
    let mut count = None;
    let mut format = false;
    let mut props: Vec<(String, Kind)> = vec![];
    let mut in_vertex = false;
    loop {
        let l = next_line(r)?;
        let words: Vec<&str> = l.split_whitespace().collect();
        match words.as_slice() {
            ["end_header"] => break,
            ["format", f, v] => {
                if *f != "binary_little_endian" || *v != "1.0" {
                    return Err(PlyError::Format(format!("{f} {v}")));
                }
                format = true;
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            ["element", name, n] => {
                if count.is_some() && in_vertex {
                    return Err(PlyError::Header(format!(
                        "element `{name}` after `vertex` is not supported"
                    )));
                }
                in_vertex = *name == "vertex";
                if !in_vertex {
                    return Err(PlyError::Header(format!(
                        "element `{name}` before `vertex` is not supported"
                    )));
                }
                count = Some(
                    n.parse::<usize>()
                        .map_err(|_| PlyError::Header(format!("bad vertex count `{n}`")))?,
                );
            }
            ["property", "list", ..] => {
                return Err(PlyError::Header("list properties are not supported".into()));
            }
            ["property", ty, name] => {
                let kind = Kind::parse(ty).ok_or_else(|| {
                    PlyError::Header(format!("property type `{ty}` is not supported"))
                })?;
                props.push((name.to_string(), kind));
            }
            _ => return Err(PlyError::Header(format!("unexpected line `{l}`"))),
        }
    }
    if !format {
        return Err(PlyError::Header(
            "no `format` line (binary_little_endian 1.0 expected)".into(),
        ));
    }
    let count = count.ok_or_else(|| PlyError::Header("no `element vertex`".into()))?;
    let index: HashMap<&str, usize> = props
        .iter()
        .enumerate()
        .map(|(i, (n, _))| (n.as_str(), i))
        .collect();
    // A Gaussian's properties are real numbers: a byte would be read as 0..255.
    let find = |n: &str| match index.get(n) {
        None => Err(PlyError::Missing(n.into())),
        Some(&i) if matches!(props[i].1, Kind::U8) => Err(PlyError::Header(format!(
            "property `{n}` is a byte: a Gaussian's properties are float or double"
        ))),
        Some(&i) => Ok(i),
    };
    let rest = (0..)
        .take_while(|k| index.contains_key(format!("f_rest_{k}").as_str()))
        .count();
    let named_rest = props
        .iter()
        .filter(|(n, _)| n.starts_with("f_rest_"))
        .count();
    if named_rest != rest {
        return Err(PlyError::Header(format!(
            "{named_rest} f_rest properties, but f_rest_{rest} is missing (they are numbered from 0)"
        )));
    }
    let sh_degree = match rest {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        n => return Err(PlyError::ShCount(n)),
    };
    let per_channel = sh_coefficients(sh_degree) - 1;
    let mean = [find("x")?, find("y")?, find("z")?];
    let dc = [find("f_dc_0")?, find("f_dc_1")?, find("f_dc_2")?];
    let rest_idx: Vec<usize> = (0..rest)
        .map(|k| find(&format!("f_rest_{k}")))
        .collect::<Result<_, _>>()?;
    let opacity = find("opacity")?;
    let scale = [find("scale_0")?, find("scale_1")?, find("scale_2")?];
    let rot = [
        find("rot_0")?,
        find("rot_1")?,
        find("rot_2")?,
        find("rot_3")?,
    ];
    let filter_3d = ["filter_3D", "filter_3d"]
        .into_iter()
        .find(|n| index.contains_key(n))
        .map(find)
        .transpose()?;

    let offsets: Vec<usize> = props
        .iter()
        .scan(0, |at, (_, k)| {
            let o = *at;
            *at += k.size();
            Some(o)
        })
        .collect();
    let stride: usize = props.iter().map(|(_, k)| k.size()).sum();
    let mut data = Vec::new();
    (Read::take(&mut *r, count as u64 * stride as u64))
        .read_to_end(&mut data)
        .map_err(|e| PlyError::Header(e.to_string()))?;
    let found = data.len() / stride.max(1);
    if found < count {
        return Err(PlyError::Truncated {
            expected: count,
            found,
        });
    }
    let mut gaussians = Vec::with_capacity(count);
    for i in 0..count {
        let row = &data[i * stride..(i + 1) * stride];
        let get = |p: usize| -> Result<f32, PlyError> {
            let o = offsets[p];
            let v = match props[p].1 {
                Kind::F32 => f32::from_le_bytes(row[o..o + 4].try_into().unwrap()),
                Kind::F64 => f64::from_le_bytes(row[o..o + 8].try_into().unwrap()) as f32,
                Kind::U8 => row[o] as f32,
            };
            if !v.is_finite() {
                return Err(PlyError::NonFinite {
                    index: i,
                    property: props[p].0.clone(),
                    value: v,
                });
            }
            Ok(v)
        };
        let v3 = |ix: [usize; 3]| -> Result<Vec3, PlyError> {
            Ok(Vec3::new(get(ix[0])?, get(ix[1])?, get(ix[2])?))
        };
        let mut sh = [Vec3::ZERO; 16];
        sh[0] = v3(dc)?;
        for k in 0..per_channel {
            sh[k + 1] = v3([
                rest_idx[k],
                rest_idx[per_channel + k],
                rest_idx[2 * per_channel + k],
            ])?;
        }
        let mut g = StoredGaussian {
            mean: v3(mean)?,
            log_scale: v3(scale)?,
            rotation: Vec4::new(get(rot[0])?, get(rot[1])?, get(rot[2])?, get(rot[3])?),
            opacity_logit: get(opacity)?,
            sh,
        };
        if let Some(f) = filter_3d {
            fold_3d_filter(&mut g, get(f)?);
        }
        gaussians.push(g);
    }
    Ok(GaussianCloud {
        sh_degree,
        gaussians,
        folded_3d_filter: filter_3d.is_some(),
        antialiased: false,
    })
}

/// Folds a 3D smoothing filter of standard deviation `filter` into the Gaussian: each
/// squared scale s² becomes s² + filter², and the opacity is multiplied by
/// sqrt(Π s² / Π (s² + filter²)). Computed in logs (f64), so that no scale or opacity that
/// f32 holds underflows or saturates on the way.
fn fold_3d_filter(g: &mut StoredGaussian, filter: f32) {
    if filter == 0.0 {
        return;
    }
    let ln_filter = f64::from(filter.abs()).ln();
    // ln(e^a + e^b), exact where one term is far below the other.
    let ln_add = |a: f64, b: f64| a.max(b) + (-(a - b).abs()).exp().ln_1p();
    let mut ln_coef = 0.0;
    for s in g.log_scale.as_mut() {
        let ln_s = f64::from(*s);
        let ln_widened = 0.5 * ln_add(2.0 * ln_s, 2.0 * ln_filter);
        ln_coef += ln_s - ln_widened;
        *s = ln_widened as f32;
    }
    // logit(sigmoid(o) coef) = ln p - ln(1 - p), with ln sigmoid(o) = -ln(1 + e^-o).
    let o = f64::from(g.opacity_logit);
    let ln_sigmoid = -ln_add(0.0, -o);
    let ln_p = ln_sigmoid + ln_coef;
    g.opacity_logit = (ln_p - (-ln_p.exp()).ln_1p()) as f32;
}

/// Writes the cloud in the INRIA layout (with zero normals), atomically.
pub fn write(path: &Path, cloud: &GaussianCloud) -> std::io::Result<()> {
    super::write_atomic(path, |w| write_to(w, cloud))
}

/// Refused, as [`parse`] would refuse the file: an SH degree above 3, a NaN or infinite value.
pub fn write_to(w: &mut dyn Write, cloud: &GaussianCloud) -> std::io::Result<()> {
    let refuse = |why: String| Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, why));
    if cloud.sh_degree > 3 {
        return refuse(format!(
            "SH degree {} cannot be stored (0 to 3)",
            cloud.sh_degree
        ));
    }
    cloud.check_finite()?;
    let per_channel = sh_coefficients(cloud.sh_degree) - 1;
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\n",
        cloud.gaussians.len()
    );
    let mut names: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    names.extend((0..3 * per_channel).map(|k| format!("f_rest_{k}")));
    names.extend(
        [
            "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ]
        .map(String::from),
    );
    for n in &names {
        header.push_str(&format!("property float {n}\n"));
    }
    header.push_str("end_header\n");
    w.write_all(header.as_bytes())?;
    for g in &cloud.gaussians {
        let mut row: Vec<f32> = vec![g.mean.x, g.mean.y, g.mean.z, 0.0, 0.0, 0.0];
        row.extend(g.sh[0].to_array());
        for ch in 0..3 {
            row.extend((0..per_channel).map(|k| g.sh[k + 1][ch]));
        }
        row.push(g.opacity_logit);
        row.extend(g.log_scale.to_array());
        row.extend(g.rotation.to_array());
        for v in row {
            w.write_all(&v.to_le_bytes())?;
        }
    }
    Ok(())
}

impl StoredGaussian {
    pub fn is_finite(&self) -> bool {
        let mut vectors = [self.mean, self.log_scale].into_iter().chain(self.sh);
        vectors.all(|v| v.is_finite())
            && self.rotation.is_finite()
            && self.opacity_logit.is_finite()
    }
}

impl GaussianCloud {
    /// A cloud of SH degree `sh_degree`, without flags.
    pub fn new(sh_degree: u32, gaussians: Vec<StoredGaussian>) -> GaussianCloud {
        GaussianCloud {
            sh_degree,
            gaussians,
            folded_3d_filter: false,
            antialiased: false,
        }
    }

    /// An error naming the first Gaussian with a NaN or infinite value, which no format
    /// stores; what every writer checks first.
    pub fn check_finite(&self) -> std::io::Result<()> {
        match self.gaussians.iter().position(|g| !g.is_finite()) {
            None => Ok(()),
            Some(i) => Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("Gaussian {i} has a NaN or infinite value"),
            )),
        }
    }

    /// The cloud as a method's parameters.
    pub fn params<P: FromStored>(&self) -> Vec<P> {
        self.gaussians.iter().map(P::from_stored).collect()
    }
}

/// Parameters that can be built from a Gaussian stored in an INRIA PLY file (how `splat render`
/// reads a scene for a method).
pub trait FromStored {
    fn from_stored(g: &StoredGaussian) -> Self;
}

/// Parameters that can be stored as a Gaussian of an INRIA PLY file (what `splat fit` writes).
pub trait ToStored {
    fn to_stored(&self) -> StoredGaussian;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(degree: u32) -> GaussianCloud {
        let mut rng = 0.5f32;
        let mut next = || {
            rng = (rng * 3.7 + 0.13).fract();
            rng - 0.5
        };
        let gaussians = (0..5)
            .map(|_| {
                let mut sh = [Vec3::ZERO; 16];
                for c in sh.iter_mut().take(sh_coefficients(degree)) {
                    *c = Vec3::new(next(), next(), next());
                }
                StoredGaussian {
                    mean: Vec3::new(next(), next(), next()),
                    log_scale: Vec3::new(next(), next(), next()),
                    rotation: Vec4::new(1.0, next(), next(), next()),
                    opacity_logit: next(),
                    sh,
                }
            })
            .collect();
        GaussianCloud::new(degree, gaussians)
    }

    #[test]
    fn round_trips_every_sh_degree() {
        for degree in 0..=3 {
            let c = cloud(degree);
            let mut bytes = vec![];
            write_to(&mut bytes, &c).unwrap();
            let back = parse(&mut bytes.as_slice()).unwrap();
            assert_eq!(back, c);
        }
    }

    #[test]
    fn channel_major_rest_coefficients() {
        // Degree 1: f_rest_0..2 are R of the three degree-1 functions, then G, then B.
        let mut c = cloud(1);
        c.gaussians.truncate(1);
        c.gaussians[0].sh[1] = Vec3::new(1.0, 2.0, 3.0);
        c.gaussians[0].sh[2] = Vec3::new(4.0, 5.0, 6.0);
        c.gaussians[0].sh[3] = Vec3::new(7.0, 8.0, 9.0);
        let mut bytes = vec![];
        write_to(&mut bytes, &c).unwrap();
        let body = &bytes[bytes.len() - 4 * (9 + 9 + 8)..];
        let f = |k: usize| f32::from_le_bytes(body[4 * k..4 * k + 4].try_into().unwrap());
        let rest: Vec<f32> = (9..18).map(f).collect();
        assert_eq!(rest, [1.0, 4.0, 7.0, 2.0, 5.0, 8.0, 3.0, 6.0, 9.0]);
    }

    #[test]
    fn malformed_files_get_clear_errors() {
        let c = cloud(3);
        let mut bytes = vec![];
        write_to(&mut bytes, &c).unwrap();
        let truncated = &bytes[..bytes.len() - 10];
        let e = parse(&mut &truncated[..]).unwrap_err().to_string();
        assert!(e.contains("truncated") && e.contains("expected 5"), "{e}");

        let text = String::from_utf8_lossy(&bytes)
            .replace("property float opacity\n", "property float opacitx\n");
        let e = parse(&mut text.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("missing property `opacity`"), "{e}");

        let e = parse(&mut &b"hello"[..]).unwrap_err().to_string();
        assert!(e.contains("not a PLY"), "{e}");

        let ascii = b"ply\nformat ascii 1.0\nelement vertex 0\nend_header\n";
        assert!(
            parse(&mut &ascii[..])
                .unwrap_err()
                .to_string()
                .contains("ascii")
        );

        let text = String::from_utf8_lossy(&bytes);
        let gap = text.replace("property float f_rest_3\n", "property float f_rest_99\n");
        let e = parse(&mut gap.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("but f_rest_3 is missing"), "{e}");
        let formatless = text.replace("format binary_little_endian 1.0\n", "");
        let e = parse(&mut formatless.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("no `format` line"), "{e}");
        let byte = text.replace("property float opacity\n", "property uchar opacity\n");
        let e = parse(&mut byte.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("property `opacity` is a byte"), "{e}");

        // The writer refuses NaN (as the reader does): one written finite, then made NaN.
        let mut nan = c.clone();
        nan.gaussians[2].mean.y = f32::NAN;
        let e = write_to(&mut vec![], &nan).unwrap_err().to_string();
        assert!(e.contains("Gaussian 2 has a NaN"), "{e}");
        nan.gaussians[2].mean.y = 1234.5;
        let mut bytes = vec![];
        write_to(&mut bytes, &nan).unwrap();
        let at = (bytes.windows(4))
            .position(|w| w == 1234.5f32.to_le_bytes())
            .unwrap();
        bytes[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        let e = parse(&mut bytes.as_slice()).unwrap_err().to_string();
        assert!(e.contains("vertex 2") && e.contains("`y`"), "{e}");
        let degree4 = GaussianCloud { sh_degree: 4, ..c };
        let e = write_to(&mut vec![], &degree4).unwrap_err().to_string();
        assert!(e.contains("SH degree 4 cannot be stored"), "{e}");
    }

    /// `cloud` as Mip-Splatting writes it: an extra `filter_3D` property per vertex.
    fn with_filter(c: &GaussianCloud, filters: &[f32]) -> Vec<u8> {
        let mut bytes = vec![];
        write_to(&mut bytes, c).unwrap();
        let end = b"end_header\n";
        let at = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let mut out = bytes[..at - end.len()].to_vec();
        out.extend(b"property float filter_3D\n");
        out.extend(end);
        let stride = (bytes.len() - at) / c.gaussians.len();
        for (row, f) in bytes[at..].chunks(stride).zip(filters) {
            out.extend(row);
            out.extend(f.to_le_bytes());
        }
        out
    }

    /// Mip-Splatting's 3D filter is folded in as its fused export does: s² + f² per axis,
    /// and the opacity scaled by sqrt(Π s² / Π (s² + f²)) (computed here directly in f64).
    #[test]
    fn mip_splatting_filters_are_folded_in() {
        let mut c = cloud(0);
        // Ordinary, tiny (the filter dominates), saturated opacity, and no filter.
        c.gaussians[1].log_scale = Vec3::splat(-30.0);
        c.gaussians[2].opacity_logit = 40.0;
        let filters = [0.05, 0.01, 0.002, 0.0, 0.3];
        let read = parse(&mut with_filter(&c, &filters).as_slice()).unwrap();
        let mut plain = vec![];
        write_to(&mut plain, &c).unwrap();
        assert!(read.folded_3d_filter && !parse(&mut plain.as_slice()).unwrap().folded_3d_filter);
        for ((before, after), f) in c.gaussians.iter().zip(&read.gaussians).zip(filters) {
            let f = f64::from(f);
            let (mut det_before, mut det_after) = (1.0, 1.0);
            for (s, s_after) in before
                .log_scale
                .to_array()
                .iter()
                .zip(after.log_scale.to_array())
            {
                let s2 = (2.0 * f64::from(*s)).exp();
                let expected = s2 + f * f;
                let got = (2.0 * f64::from(s_after)).exp();
                assert!((got / expected - 1.0).abs() < 1e-6, "{got} vs {expected}");
                det_before *= s2;
                det_after *= expected;
            }
            let sigmoid = |o: f64| 1.0 / (1.0 + (-o).exp());
            let p = sigmoid(f64::from(before.opacity_logit)) * (det_before / det_after).sqrt();
            let expected = (p / (1.0 - p)).ln();
            let got = f64::from(after.opacity_logit);
            assert!(
                (got - expected).abs() < 1e-5 * expected.abs().max(1.0),
                "{got} vs {expected}"
            );
            assert_eq!(
                (after.mean, after.rotation, after.sh),
                (before.mean, before.rotation, before.sh)
            );
        }
        assert_eq!(read.gaussians[3], c.gaussians[3], "no filter, no change");
    }

    /// A stream that never ends is read no further than the header's lines and vertices say.
    #[test]
    fn endless_streams_are_read_only_as_far_as_needed() {
        let zeros = || std::io::BufReader::new(std::io::repeat(0));
        let e = parse(&mut zeros()).unwrap_err().to_string();
        assert!(e.contains("not a PLY"), "{e}");
        let after_magic = std::io::Read::chain(&b"ply\n"[..], std::io::repeat(0));
        let e = (parse(&mut std::io::BufReader::new(after_magic)).unwrap_err()).to_string();
        assert!(e.contains("a header line runs past 16 MiB"), "{e}");
        // A whole cloud followed by endless bytes: its vertices, and nothing more, are read.
        let c = cloud(1);
        let mut bytes = vec![];
        write_to(&mut bytes, &c).unwrap();
        let endless = std::io::Read::chain(bytes.as_slice(), std::io::repeat(7));
        assert_eq!(parse(&mut std::io::BufReader::new(endless)).unwrap(), c);
    }
}
