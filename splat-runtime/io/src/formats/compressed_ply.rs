//! PlayCanvas's compressed PLY (`.compressed.ply`, `docs/formats-spec.md` §2): Gaussians in
//! Morton order, cut into chunks of 256; each chunk stores the range of its positions, log
//! scales and colors (18 floats), each Gaussian four 32-bit words quantized within its
//! chunk's ranges (position and log scale 11-10-11 bits, color 8 bits a channel with opacity,
//! rotation as the largest component's index and the other three in 10 bits), and SH past the
//! DC term in a byte each (`v / 8 + 0.5` in 1/256). Written as splat-transform 3.10.2 writes
//! it (same order, same bytes); read from its files, SuperSplat's and the older 12-float
//! chunks without color ranges. The comment `SplatRenderMode: mip` says it is antialiased.

use crate::ply::{GaussianCloud, StoredGaussian, sh_coefficients};
use glam::{Vec3, Vec4};
use std::io::Write;

/// Gaussians a chunk.
const CHUNK: usize = 256;
/// The chunk record's floats: position, log scale and color ranges (min x y z, max x y z).
const CHUNK_FLOATS: [&str; 18] = [
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "min_scale_x",
    "min_scale_y",
    "min_scale_z",
    "max_scale_x",
    "max_scale_y",
    "max_scale_z",
    "min_r",
    "min_g",
    "min_b",
    "max_r",
    "max_g",
    "max_b",
];
const WORDS: [&str; 4] = [
    "packed_position",
    "packed_rotation",
    "packed_scale",
    "packed_color",
];
/// The DC term's factor: color = 0.5 + SH_C0 dc (as splat-transform, in f64).
const SH_C0: f64 = 0.282_094_791_773_878_14;
/// Log scales past this are clamped in a chunk's range ("sometimes values are at infinity").
const MOST_LOG_SCALE: f32 = 20.0;
/// The comment that says the scene renders antialiased (splat-transform's, SuperSplat's).
const MIP: &str = "SplatRenderMode: mip";
/// How far into a file its header may run.
const MOST_HEADER: usize = 1 << 20;

/// Whether a PLY file's start (`head`) is a compressed PLY's header: one with a `chunk`
/// element, which the INRIA reader refuses.
pub fn is_compressed(head: &[u8]) -> bool {
    let end = find(head, b"end_header").unwrap_or(head.len());
    (head[..end].split(|b| *b == b'\n')).any(|line| line.starts_with(b"element chunk "))
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

/// One element of the header: its name, row count and properties (name, type).
struct Element {
    name: String,
    count: usize,
    properties: Vec<(String, String)>,
}

/// The bytes of one value of PLY type `ty`.
fn type_size(name: &str, ty: &str) -> Result<usize, String> {
    match ty {
        "char" | "uchar" | "int8" | "uint8" => Ok(1),
        "short" | "ushort" | "int16" | "uint16" => Ok(2),
        "int" | "uint" | "float" | "int32" | "uint32" | "float32" => Ok(4),
        "double" | "float64" => Ok(8),
        _ => Err(format!("property `{name}` has an unknown type `{ty}`")),
    }
}

impl Element {
    fn stride(&self) -> Result<usize, String> {
        (self.properties.iter())
            .map(|(n, ty)| type_size(n, ty))
            .sum()
    }

    /// The byte offset in a row of property `name`, which must have one of the types `ty`.
    fn offset(&self, name: &str, ty: &[&str]) -> Result<Option<usize>, String> {
        let mut at = 0;
        for (n, t) in &self.properties {
            if n == name {
                if !ty.contains(&t.as_str()) {
                    return Err(format!(
                        "property `{name}` of `{}` is {t}, {} expected",
                        self.name, ty[0]
                    ));
                }
                return Ok(Some(at));
            }
            at += type_size(n, t)?;
        }
        Ok(None)
    }
}

/// The header's elements, its comments and the offset of the body.
fn parse_header(bytes: &[u8]) -> Result<(Vec<Element>, Vec<String>, usize), String> {
    let end = find(&bytes[..bytes.len().min(MOST_HEADER)], b"end_header\n")
        .ok_or("no `end_header` line in its first MiB")?;
    let text = std::str::from_utf8(&bytes[..end]).map_err(|_| "its header is not text")?;
    let mut lines = text.lines();
    if lines.next() != Some("ply") {
        return Err("not a PLY file (it must start with `ply`)".into());
    }
    let mut elements: Vec<Element> = vec![];
    let mut comments = vec![];
    let mut format = false;
    for line in lines {
        match line.split_whitespace().collect::<Vec<_>>().as_slice() {
            ["format", "binary_little_endian", "1.0"] => format = true,
            ["format", f, v] => {
                return Err(format!(
                    "unsupported PLY format `{f} {v}`: only binary_little_endian 1.0"
                ));
            }
            ["comment", ..] => {
                comments.push(line.trim_start()["comment".len()..].trim().to_string())
            }
            ["obj_info", ..] | [] => {}
            ["element", name, n] => elements.push(Element {
                name: name.to_string(),
                count: n
                    .parse()
                    .map_err(|_| format!("element `{name}` has a bad count `{n}`"))?,
                properties: vec![],
            }),
            ["property", "list", ..] => return Err("list properties are not supported".into()),
            ["property", ty, name] => (elements.last_mut())
                .ok_or(format!("property `{name}` before any element"))?
                .properties
                .push((name.to_string(), ty.to_string())),
            _ => return Err(format!("unexpected header line `{line}`")),
        }
    }
    if !format {
        return Err("no `format` line (binary_little_endian 1.0 expected)".into());
    }
    Ok((elements, comments, end + b"end_header\n".len()))
}

/// `bytes` (a whole `.compressed.ply` file) as a cloud; why not, when they are not one.
pub fn parse(bytes: &[u8]) -> Result<GaussianCloud, String> {
    let (elements, comments, body) = parse_header(bytes)?;
    let element = |name: &str| elements.iter().find(|e| e.name == name);
    let chunk = element("chunk").ok_or("no `chunk` element: not a compressed PLY")?;
    let vertex = element("vertex").ok_or("no `vertex` element")?;
    if let Some(other) = (elements.iter()).find(|e| !["chunk", "vertex", "sh"].contains(&&*e.name))
    {
        return Err(format!("unknown element `{}`", other.name));
    }
    let n = vertex.count;
    if chunk.count != n.div_ceil(CHUNK) {
        return Err(format!(
            "{} chunks for {n} Gaussians ({} expected, one per {CHUNK})",
            chunk.count,
            n.div_ceil(CHUNK)
        ));
    }
    // Where each element's rows start; the file must hold them all before anything is made.
    let mut at = body;
    let mut starts = vec![];
    for e in &elements {
        starts.push(at);
        let length = (e.stride()?)
            .checked_mul(e.count)
            .and_then(|l| l.checked_add(at))
            .filter(|end| *end <= bytes.len());
        at = length.ok_or_else(|| {
            format!(
                "truncated: its `{}` element runs past the file's {} bytes",
                e.name,
                bytes.len()
            )
        })?;
    }
    // Where an element's rows start (an absent one has none to read).
    let start =
        |name: &str| (elements.iter().position(|e| e.name == name)).map_or(0, |k| starts[k]);

    let float = ["float", "float32"];
    let chunk_at: Vec<Option<usize>> = (CHUNK_FLOATS.iter())
        .map(|p| chunk.offset(p, &float))
        .collect::<Result<_, _>>()?;
    if let Some(p) = (0..12).find(|&p| chunk_at[p].is_none()) {
        return Err(format!("missing chunk property `{}`", CHUNK_FLOATS[p]));
    }
    let has_color = chunk_at[12..].iter().all(Option::is_some);
    let word_at: Vec<usize> = (WORDS.iter())
        .map(|p| {
            vertex
                .offset(p, &["uint", "uint32"])?
                .ok_or(format!("missing vertex property `{p}`"))
        })
        .collect::<Result<_, _>>()?;
    let (sh_degree, sh_at) = match element("sh") {
        None => (0, vec![]),
        Some(sh) => {
            let rest = (0..)
                .take_while(|k| (sh.properties.iter()).any(|(p, _)| *p == format!("f_rest_{k}")));
            let degree = match rest.count() {
                9 => 1,
                24 => 2,
                45 => 3,
                k => {
                    return Err(format!(
                        "{k} f_rest properties in `sh` (9, 24 or 45 expected)"
                    ));
                }
            };
            if sh.count != n {
                return Err(format!("{} SH rows for {n} Gaussians", sh.count));
            }
            let at: Vec<usize> = (0..3 * (sh_coefficients(degree) - 1))
                .map(|k| {
                    Ok(sh
                        .offset(&format!("f_rest_{k}"), &["uchar", "uint8"])?
                        .unwrap())
                })
                .collect::<Result<_, String>>()?;
            (degree, at)
        }
    };

    let (chunk_stride, vertex_stride) = (chunk.stride()?, vertex.stride()?);
    let sh_stride = element("sh").map_or(Ok(0), Element::stride)?;
    let f32_at = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes"));
    let per_channel = sh_coefficients(sh_degree) - 1;
    let mut gaussians = Vec::with_capacity(n);
    for i in 0..n {
        let c = start("chunk") + (i / CHUNK) * chunk_stride;
        let range = |p: usize| chunk_at[p].map(|o| f32_at(c + o));
        let lo_hi = |first: usize| {
            let v = |k| Vec3::from_array(std::array::from_fn(|a| range(first + k + a).unwrap()));
            (v(0), v(3))
        };
        let v = start("vertex") + i * vertex_stride;
        let word = |k: usize| u32::from_le_bytes(bytes[v + word_at[k]..][..4].try_into().unwrap());
        let (lo, hi) = lo_hi(0);
        let mean = lerp(lo, hi, unpack_111011(word(0)));
        let (lo, hi) = lo_hi(6);
        let log_scale = lerp(lo, hi, unpack_111011(word(2)));
        let color = word(3);
        let bytes4 = [24, 16, 8, 0].map(|shift| unorm(color >> shift, 8));
        let mut rgb = Vec3::new(bytes4[0], bytes4[1], bytes4[2]);
        if has_color {
            let (lo, hi) = lo_hi(12);
            rgb = lerp(lo, hi, rgb);
        }
        let mut sh = [Vec3::ZERO; 16];
        sh[0] = ((rgb.as_dvec3() - 0.5) / SH_C0).as_vec3();
        let s = start("sh") + i * sh_stride;
        for k in 0..per_channel {
            sh[k + 1] = Vec3::from_array(std::array::from_fn(|channel| {
                sh_value(bytes[s + sh_at[channel * per_channel + k]])
            }));
        }
        // Half a step in from 0 and 1, so that the logit stays finite.
        let alpha = bytes4[3].clamp(0.5 / 255.0, 1.0 - 0.5 / 255.0);
        let g = StoredGaussian {
            mean,
            log_scale,
            rotation: unpack_rotation(word(1)),
            opacity_logit: (alpha / (1.0 - alpha)).ln(),
            sh,
        };
        let finite = [g.mean, g.log_scale, g.sh[0]].iter().all(|v| v.is_finite());
        if !finite {
            return Err(format!(
                "Gaussian {i}: its chunk's ranges are NaN or infinite"
            ));
        }
        gaussians.push(g);
    }
    Ok(GaussianCloud {
        antialiased: comments.iter().any(|c| c == MIP),
        ..GaussianCloud::new(sh_degree, gaussians)
    })
}

/// Per axis, `t` of the way from `lo` to `hi` (as PlayCanvas's readers compute it).
fn lerp(lo: Vec3, hi: Vec3, t: Vec3) -> Vec3 {
    lo * (1.0 - t) + hi * t
}

fn unorm(v: u32, bits: u32) -> f32 {
    let most = (1 << bits) - 1;
    (v & most) as f32 / most as f32
}

fn unpack_111011(word: u32) -> Vec3 {
    Vec3::new(
        unorm(word >> 21, 11),
        unorm(word >> 11, 10),
        unorm(word, 11),
    )
}

/// An SH byte's value: the middle of its 1/256 step (the writer truncates), its ends exact.
fn sh_value(b: u8) -> f32 {
    let n = match b {
        0 => 0.0,
        255 => 1.0,
        b => (b as f32 + 0.5) / 256.0,
    };
    (n - 0.5) * 8.0
}

/// The largest component's slot in the top two bits, the others (in slot order) as 10-bit
/// unorms of `q / sqrt 2 + 0.5`.
fn unpack_rotation(word: u32) -> Vec4 {
    let largest = (word >> 30) as usize;
    let mut q = [0.0f32; 4];
    let mut shift = 30;
    for (i, slot) in q.iter_mut().enumerate() {
        if i != largest {
            shift -= 10;
            *slot = (unorm(word >> shift, 10) - 0.5) * std::f32::consts::SQRT_2;
        }
    }
    q[largest] = (1.0 - q.iter().map(|v| v * v).sum::<f32>()).max(0.0).sqrt();
    Vec4::from_array(q)
}

/// Writes `cloud` as a compressed PLY, in Morton order (its Gaussians reordered). Refused: a
/// NaN or infinite value.
pub fn write_to(w: &mut dyn Write, cloud: &GaussianCloud) -> std::io::Result<()> {
    cloud.check_finite()?;
    let n = cloud.gaussians.len();
    let degree = cloud.sh_degree.min(3);
    let rest = sh_coefficients(degree) - 1;
    let mut header = vec![
        "ply".to_string(),
        "format binary_little_endian 1.0".into(),
        format!("comment Generated by splat {}", env!("CARGO_PKG_VERSION")),
    ];
    if cloud.antialiased {
        header.push(format!("comment {MIP}"));
    }
    header.push(format!("element chunk {}", n.div_ceil(CHUNK)));
    header.extend(CHUNK_FLOATS.map(|p| format!("property float {p}")));
    header.push(format!("element vertex {n}"));
    header.extend(WORDS.map(|p| format!("property uint {p}")));
    if degree > 0 {
        header.push(format!("element sh {n}"));
        header.extend((0..3 * rest).map(|k| format!("property uchar f_rest_{k}")));
    }
    header.push("end_header\n".into());
    w.write_all(header.join("\n").as_bytes())?;

    let means: Vec<Vec3> = cloud.gaussians.iter().map(|g| g.mean).collect();
    let order = super::morton::order(&means);
    let chunks: Vec<Chunk> = (order.chunks(CHUNK))
        .map(|members| Chunk::pack(members.iter().map(|&i| &cloud.gaussians[i])))
        .collect();
    let mut body = Vec::with_capacity(n * (16 + 3 * rest) + chunks.len() * 72);
    for c in &chunks {
        body.extend(c.ranges.iter().flat_map(|v| v.to_le_bytes()));
    }
    for c in &chunks {
        body.extend(c.words.iter().flatten().flat_map(|v| v.to_le_bytes()));
    }
    for &i in &order {
        // Channel-major, as the INRIA PLY's f_rest.
        let rest = &cloud.gaussians[i].sh[1..=rest];
        for channel in 0..3 {
            body.extend(rest.iter().map(|c| {
                let t = (f64::from(c[channel]) / 8.0 + 0.5) * 256.0;
                t.trunc().clamp(0.0, 255.0) as u8
            }));
        }
    }
    w.write_all(&body)
}

/// A chunk's ranges and its members' packed words, as splat-transform computes them.
struct Chunk {
    ranges: [f32; 18],
    words: Vec<[u32; 4]>,
}

impl Chunk {
    fn pack<'a>(members: impl Iterator<Item = &'a StoredGaussian>) -> Chunk {
        let members: Vec<&StoredGaussian> = members.collect();
        // splat-transform fills a last, partial chunk with copies of its last Gaussian: the
        // ranges are those of the members.
        let color = |g: &StoredGaussian| (g.sh[0].as_dvec3() * SH_C0 + 0.5).as_vec3();
        let range = |f: &dyn Fn(&StoredGaussian) -> Vec3| {
            let first = f(members[0]);
            (members.iter()).fold((first, first), |(lo, hi), g| (lo.min(f(g)), hi.max(f(g))))
        };
        let position = range(&|g| g.mean);
        let clamp = |v: Vec3| v.clamp(Vec3::splat(-MOST_LOG_SCALE), Vec3::splat(MOST_LOG_SCALE));
        let (lo, hi) = range(&|g| g.log_scale);
        let scale = (clamp(lo), clamp(hi));
        let rgb = range(&color);
        let mut ranges = [0.0; 18];
        for (k, v) in [position.0, position.1, scale.0, scale.1, rgb.0, rgb.1]
            .iter()
            .enumerate()
        {
            ranges[3 * k..3 * k + 3].copy_from_slice(&v.to_array());
        }
        let words = (members.iter())
            .map(|g| {
                let [r, gr, b] = normalized(color(g), rgb);
                let alpha = 1.0 / (1.0 + (-f64::from(g.opacity_logit)).exp());
                [
                    pack_111011(normalized(g.mean, position)),
                    pack_rotation(g.rotation),
                    pack_111011(normalized(g.log_scale, scale)),
                    (pack_unorm(r, 8) << 24)
                        | (pack_unorm(gr, 8) << 16)
                        | (pack_unorm(b, 8) << 8)
                        | pack_unorm(alpha, 8),
                ]
            })
            .collect();
        Chunk { ranges, words }
    }
}

/// `v` within the range (lo, hi), in [0, 1] per axis (0 where the range is under 1e-5).
fn normalized(v: Vec3, (lo, hi): (Vec3, Vec3)) -> [f64; 3] {
    std::array::from_fn(|a| {
        let (v, lo, hi) = (f64::from(v[a]), f64::from(lo[a]), f64::from(hi[a]));
        if v <= lo {
            0.0
        } else if v >= hi {
            1.0
        } else if hi - lo < 1e-5 {
            0.0
        } else {
            (v - lo) / (hi - lo)
        }
    })
}

fn pack_unorm(t: f64, bits: u32) -> u32 {
    let most = f64::from((1u32 << bits) - 1);
    (t * most + 0.5).floor().clamp(0.0, most) as u32
}

fn pack_111011([x, y, z]: [f64; 3]) -> u32 {
    (pack_unorm(x, 11) << 21) | (pack_unorm(y, 10) << 11) | pack_unorm(z, 11)
}

/// The unit quaternion (slot order as stored), the largest component made positive.
fn pack_rotation(q: Vec4) -> u32 {
    let q = q.as_dvec4();
    let length = q.length();
    let mut a = if length == 0.0 {
        [0.0, 0.0, 0.0, 1.0]
    } else {
        (q * (1.0 / length)).to_array()
    };
    let largest = (1..4).fold(0, |m, i| if a[i].abs() > a[m].abs() { i } else { m });
    if a[largest] < 0.0 {
        a = a.map(|v| -v);
    }
    let mut word = largest as u32;
    for (_, v) in a.iter().enumerate().filter(|(i, _)| *i != largest) {
        word = (word << 10) | pack_unorm(v * (2f64.sqrt() * 0.5) + 0.5, 10);
    }
    word
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: usize, degree: u32) -> GaussianCloud {
        crate::formats::random_cloud(n, degree, 5, [10.0, 5.0, 1.5, 1.5])
    }

    /// Each quantity within half a step of its chunk's range (the range over 2^bits - 1), in
    /// the order written.
    #[test]
    fn a_round_trip_keeps_each_gaussian_within_its_chunks_step() {
        for degree in 0..=3 {
            // A last chunk of 44.
            let before = cloud(2 * CHUNK + 44, degree);
            let mut bytes = vec![];
            write_to(&mut bytes, &before).unwrap();
            let after = parse(&bytes).unwrap();
            assert_eq!(after.sh_degree, degree);
            let means: Vec<Vec3> = before.gaussians.iter().map(|g| g.mean).collect();
            let order = crate::formats::morton::order(&means);
            let step = Vec3::new(1.0 / 2047.0, 1.0 / 1023.0, 1.0 / 2047.0);
            let sigmoid = |x: f32| 1.0 / (1.0 + (-x).exp());
            for (chunk, members) in order.chunks(CHUNK).enumerate() {
                let span = |f: &dyn Fn(&StoredGaussian) -> Vec3| {
                    let vs = members.iter().map(|&i| f(&before.gaussians[i]));
                    let (lo, hi) =
                        vs.fold((Vec3::MAX, Vec3::MIN), |(l, h), v| (l.min(v), h.max(v)));
                    hi - lo
                };
                for (j, &i) in members.iter().enumerate() {
                    let (a, b) = (&before.gaussians[i], &after.gaussians[chunk * CHUNK + j]);
                    let within = |got: Vec3, bound: Vec3| {
                        assert!(got.cmple(bound * 1.0001 + 1e-6).all(), "{got} > {bound}")
                    };
                    within((a.mean - b.mean).abs(), 0.5 * step * span(&|g| g.mean));
                    within(
                        (a.log_scale - b.log_scale).abs(),
                        0.5 * step * span(&|g| g.log_scale),
                    );
                    let dc = span(&|g| g.sh[0]);
                    within((a.sh[0] - b.sh[0]).abs(), Vec3::splat(0.5 / 255.0) * dc);
                    let alpha = (sigmoid(a.opacity_logit) - sigmoid(b.opacity_logit)).abs();
                    assert!(alpha <= 0.5 / 255.0 + 1e-5, "{alpha}");
                    let near = crate::formats::rotation_distance(a.rotation, b.rotation);
                    assert!(near < 2e-3, "{} {}", a.rotation, b.rotation);
                    for k in 1..sh_coefficients(degree) {
                        // Truncated to 8 / 256, read at the step's middle.
                        let off = (a.sh[k] - b.sh[k]).abs().max_element();
                        assert!(off <= 4.0 / 256.0 + 1e-6, "coefficient {k}: {off}");
                    }
                }
            }
        }
    }

    #[test]
    fn rotation_packs_as_playcanvas() {
        // (w, x, y, z) = (0.9, 0.1, 0.2, 0.3), normalized: w largest, slot 0.
        let q = Vec4::new(0.9, 0.1, 0.2, 0.3).normalize();
        let word = pack_rotation(q);
        assert_eq!(word >> 30, 0);
        let third = |v: f32| ((v as f64 * 2f64.sqrt() * 0.5 + 0.5) * 1023.0 + 0.5).floor() as u32;
        assert_eq!(word & 0x3ff, third(q.w));
        assert_eq!(word >> 20 & 0x3ff, third(q.y));
        assert!((unpack_rotation(word) - q).abs().max_element() < 1e-3);
        // Negative largest: the whole quaternion negated.
        assert!((unpack_rotation(pack_rotation(-q)) - q).abs().max_element() < 1e-3);
    }

    #[test]
    fn bad_files_are_refused_with_why() {
        let mut bytes = vec![];
        write_to(&mut bytes, &cloud(300, 1)).unwrap();
        let e = parse(&bytes[..bytes.len() - 1]).unwrap_err();
        assert!(e.contains("truncated") && e.contains("`sh`"), "{e}");
        let text =
            String::from_utf8_lossy(&bytes).replacen("element chunk 2", "element chunk 3", 1);
        let e = parse(text.as_bytes()).unwrap_err();
        assert!(e.contains("3 chunks for 300 Gaussians"), "{e}");
        let huge = b"ply\nformat binary_little_endian 1.0\nelement chunk 3906250000\nproperty float min_x\nelement vertex 1000000000000\nend_header\n";
        assert!(parse(huge).unwrap_err().contains("truncated"));
        assert!(parse(b"ply\n").unwrap_err().contains("end_header"));
        let mut far = cloud(3, 0);
        far.gaussians[2].opacity_logit = f32::NAN;
        let e = write_to(&mut vec![], &far).unwrap_err().to_string();
        assert!(e.contains("Gaussian 2"), "{e}");
    }

    #[test]
    fn is_compressed_tells_the_two_plys_apart() {
        let mut compressed = vec![];
        write_to(&mut compressed, &cloud(10, 0)).unwrap();
        assert!(is_compressed(&compressed));
        let mut inria = vec![];
        crate::ply::write_to(&mut inria, &cloud(10, 0)).unwrap();
        assert!(!is_compressed(&inria));
    }
}
