//! Checkpoints: everything a training run needs to go on where it stopped (the steps done,
//! the primitives, Adam's moments, density control's statistics, the random generator, what
//! it learns per view), and their file format.
//!
//! The file is little-endian: the magic `SPLATCK8`, then `u64` counts and fields (see
//! [`Checkpoint::write_to`]), then the arrays, then the CRC-32 of all that. The checksum is
//! checked first, and every count against the file's length before anything is allocated, so
//! a damaged file is refused by name, never trusted.

use super::adam::AdamState;
use super::per_view::{Learned, PerViewState};
use splat_core::flat::Flat;
use splat_core::method::SplatMethod;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// The formats read, newest first; each lacks what the one before it added, read as unknown
/// or none: 8 added what a run learns per camera, 7 what it learns per view, 6 the checksum
/// (5 is resumed unchecked), 5 the run's settings, 4 the training views' footprint.
const FORMATS: [&[u8; 8]; 6] = [
    b"SPLATCK8",
    b"SPLATCK7",
    b"SPLATCK6",
    b"SPLATCK5",
    b"SPLATCK4",
    b"SPLATCK3",
];
const MAGIC: &[u8; 8] = FORMATS[0];
/// Earlier formats (the first without the strategy, the second without the scene's extent):
/// refused with a word on why.
const OLDER: &[&[u8; 8]] = &[b"SPLATCK1", b"SPLATCK2"];

/// A training run's state after `step` of `steps` steps.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    /// The method trained (`SplatMethod::NAME`) and its parameter words per primitive.
    pub method: String,
    pub words: usize,
    /// How the primitive set changed (`Strategy::name`), set by the loop when it saves:
    /// resuming with another strategy would silently take other steps.
    pub strategy: String,
    /// The run's other settings that change its steps ([`super::fit::settings`]), set by the
    /// loop as the strategy is; empty before, and from a checkpoint of a format before them.
    pub settings: String,
    pub step: usize,
    /// The run's length: the learning-rate schedule depends on it.
    pub steps: usize,
    /// The primitives' parameter words, one primitive after another.
    pub params: Vec<f32>,
    pub adam: AdamState,
    /// Density control's statistics since its last refinement (per primitive: summed
    /// screen-space gradient norms, views that saw it); empty without density control.
    pub grad2d: Vec<f32>,
    pub seen: Vec<u32>,
    /// The random generator's state.
    pub rng: u64,
    /// The scene's extent the run trains with (position rates and density control's sizes
    /// scale with it), set by the loop as the strategy is.
    pub extent: f32,
    /// The training views the run trains on: how many, and their pixels in all (a dataset
    /// read at another `--downscale` differs), set by the loop as the strategy is; `None`
    /// before, and from a checkpoint of the format before it (`SPLATCK3`).
    pub views: Option<ViewsFootprint>,
    /// What the run learns per training view and per camera, with its moments
    /// (`super::per_view`); empty where it learns nothing, and from a checkpoint of a format
    /// before it (`SPLATCK6`; `SPLATCK7` has no cameras').
    pub per_view: PerViewState,
}

/// How many training views a run has, and their pixels in all.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ViewsFootprint {
    pub views: u64,
    pub pixels: u64,
}

#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("cannot read {path}: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error(
        "{path} is not a splat checkpoint (it does not start with SPLATCK8, SPLATCK7, SPLATCK6, SPLATCK5, SPLATCK4 or SPLATCK3)"
    )]
    Magic { path: PathBuf },
    #[error(
        "{path} was written by an earlier splat (format {format}), which this one cannot resume: start the run again"
    )]
    Older { path: PathBuf, format: String },
    #[error("{path} is damaged: {what}")]
    Damaged { path: PathBuf, what: String },
}

impl Checkpoint {
    /// The state before the first step of a `steps`-step run of method `M` from `params`.
    pub fn start<M: SplatMethod>(params: &[M::Params], steps: usize, seed: u64) -> Checkpoint {
        Checkpoint {
            method: M::NAME.to_string(),
            words: M::Params::LEN,
            strategy: String::new(),
            settings: String::new(),
            step: 0,
            steps,
            params: splat_core::flat::flatten(params),
            adam: AdamState {
                step: 0,
                m: vec![0.0; params.len() * M::Params::LEN],
                v: vec![0.0; params.len() * M::Params::LEN],
            },
            grad2d: vec![],
            seen: vec![],
            rng: seed,
            extent: 0.0,
            views: None,
            per_view: PerViewState::default(),
        }
    }

    /// The primitives, as method `M`'s parameters.
    pub fn params<M: SplatMethod>(&self) -> Vec<M::Params> {
        self.params
            .chunks_exact(M::Params::LEN)
            .map(M::Params::read_words)
            .collect()
    }

    pub fn primitives(&self) -> usize {
        self.params.len() / self.words.max(1)
    }

    /// Primitives `range` of this state, with their moments and statistics, the rest as it
    /// is: what one rank of a sharded run holds ([`super::sharded`]).
    pub fn slice(&self, range: std::ops::Range<usize>) -> Checkpoint {
        let words = range.start * self.words..range.end * self.words;
        // Statistics are per primitive, or none at all.
        fn part<T: Copy>(v: &[T], range: &std::ops::Range<usize>) -> Vec<T> {
            v.get(range.clone()).map_or_else(Vec::new, <[T]>::to_vec)
        }
        Checkpoint {
            params: self.params[words.clone()].to_vec(),
            adam: AdamState {
                step: self.adam.step,
                m: self.adam.m[words.clone()].to_vec(),
                v: self.adam.v[words].to_vec(),
            },
            grad2d: part(&self.grad2d, &range),
            seen: part(&self.seen, &range),
            ..self.clone_head()
        }
    }

    /// Slices of one state ([`Checkpoint::slice`]) put back together in order, the rest as
    /// the first has it (`None` for no slices).
    pub fn join(parts: Vec<Checkpoint>) -> Option<Checkpoint> {
        let mut whole = parts.first()?.clone_head();
        let stats = parts.iter().any(|p| !p.grad2d.is_empty());
        for p in parts {
            let n = p.primitives();
            whole.params.extend(p.params);
            whole.adam.m.extend(p.adam.m);
            whole.adam.v.extend(p.adam.v);
            match (stats, p.grad2d.is_empty()) {
                (true, true) => {
                    whole.grad2d.extend(std::iter::repeat_n(0.0, n));
                    whole.seen.extend(std::iter::repeat_n(0, n));
                }
                (true, false) => {
                    whole.grad2d.extend(p.grad2d);
                    whole.seen.extend(p.seen);
                }
                (false, _) => {}
            }
        }
        Some(whole)
    }

    /// Everything but the primitives' words, moments and statistics (the per-view state is
    /// the whole run's on every slice).
    pub fn clone_head(&self) -> Checkpoint {
        Checkpoint {
            method: self.method.clone(),
            words: self.words,
            strategy: self.strategy.clone(),
            settings: self.settings.clone(),
            step: self.step,
            steps: self.steps,
            params: vec![],
            adam: AdamState {
                step: self.adam.step,
                m: vec![],
                v: vec![],
            },
            grad2d: vec![],
            seen: vec![],
            rng: self.rng,
            extent: self.extent,
            views: self.views,
            per_view: self.per_view.clone(),
        }
    }

    /// What makes this state no run's (its fields are public, so a caller can build one):
    /// parameters that are not whole primitives, moments or statistics of another size, a
    /// step past the run's end. `read` refuses a file that holds such a state.
    pub fn size_defect(&self) -> Option<String> {
        let (words, params) = (self.words, self.params.len());
        let (m, v) = (self.adam.m.len(), self.adam.v.len());
        let (stats, seen) = (self.grad2d.len(), self.seen.len());
        if words == 0 || params % words != 0 {
            Some(format!(
                "{params} parameter words are not whole primitives of {words} words"
            ))
        } else if m != params || v != params {
            Some(format!(
                "Adam's moments hold {m} and {v} words, the parameters {params}"
            ))
        } else if stats != seen || (stats != 0 && stats != self.primitives()) {
            Some(format!(
                "density control's statistics are for {stats} and {seen} primitives, the parameters for {}",
                self.primitives()
            ))
        } else if let Some(defect) = [
            (&self.per_view.views, "views"),
            (&self.per_view.cameras, "cameras"),
        ]
        .into_iter()
        .find(|(l, _)| l.units(l.words_per_unit()).is_none())
        {
            let (l, what) = defect;
            Some(format!(
                "the learned state of the {what} holds {} words, {} and {} moments for {} {what}",
                l.words.len(),
                l.m.len(),
                l.v.len(),
                l.steps.len()
            ))
        } else if self.step > self.steps {
            Some(format!(
                "step {} is past the run's {} steps",
                self.step, self.steps
            ))
        } else {
            None
        }
    }

    /// Writes the checkpoint to `path` atomically (a run killed while writing leaves the
    /// previous checkpoint).
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        splat_io::write_atomic(path, |w| self.write_to(w))
    }

    /// The checkpoint's file as bytes ([`Checkpoint::parse`] reads them back).
    pub fn to_bytes(&self) -> std::io::Result<Vec<u8>> {
        let mut bytes = vec![];
        self.write_to(&mut bytes)?;
        Ok(bytes)
    }

    /// The header (magic, method name, strategy name, settings, then words, step, steps,
    /// primitives, Adam's step, statistics count, generator state, the extent's bits as `u64`,
    /// the training views and their pixels, 0 and 0 for none), then the parameters, both
    /// moments and the statistics, then what the run learned per view and then per camera
    /// (each: units, words per unit, the words, both moments, each unit's step count), then
    /// the CRC-32 of every byte before it.
    pub fn write_to(&self, w: &mut dyn Write) -> std::io::Result<()> {
        if let Some(defect) = self.size_defect() {
            let what = format!("not a run's state: {defect}");
            return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, what));
        }
        let mut summed = Summed {
            w,
            crc: crc32fast::Hasher::new(),
        };
        self.write_fields(&mut summed)?;
        let crc = summed.crc.finalize();
        summed.w.write_all(&crc.to_le_bytes())
    }

    /// What [`write_to`](Self::write_to) writes before the checksum.
    fn write_fields(&self, w: &mut dyn Write) -> std::io::Result<()> {
        w.write_all(MAGIC)?;
        for name in [&self.method, &self.strategy, &self.settings] {
            w.write_all(&(name.len() as u64).to_le_bytes())?;
            w.write_all(name.as_bytes())?;
        }
        for n in [
            self.words as u64,
            self.step as u64,
            self.steps as u64,
            self.primitives() as u64,
            self.adam.step,
            self.grad2d.len() as u64,
            self.rng,
            self.extent.to_bits() as u64,
            self.views.map_or(0, |v| v.views),
            self.views.map_or(0, |v| v.pixels),
        ] {
            w.write_all(&n.to_le_bytes())?;
        }
        for words in [&self.params, &self.adam.m, &self.adam.v, &self.grad2d] {
            write_f32s(w, words)?;
        }
        for s in &self.seen {
            w.write_all(&s.to_le_bytes())?;
        }
        for l in [&self.per_view.views, &self.per_view.cameras] {
            for n in [l.steps.len(), l.words_per_unit()] {
                w.write_all(&(n as u64).to_le_bytes())?;
            }
            for words in [&l.words, &l.m, &l.v] {
                write_f32s(w, words)?;
            }
            for s in &l.steps {
                w.write_all(&s.to_le_bytes())?;
            }
        }
        Ok(())
    }

    pub fn read(path: &Path) -> Result<Checkpoint, CheckpointError> {
        let io = |error| CheckpointError::Io {
            path: path.to_path_buf(),
            error,
        };
        let mut file = std::fs::File::open(path).map_err(io)?;
        // A checkpoint is a file of known length: a device or pipe (`/dev/zero`) is not read
        // without end.
        if !file.metadata().map_err(io)?.is_file() {
            return Err(io(std::io::Error::other("it is not a regular file")));
        }
        let mut bytes = vec![];
        file.read_to_end(&mut bytes).map_err(io)?;
        Checkpoint::parse(&bytes, path)
    }

    /// Parses a checkpoint file's bytes (`path` names it in errors).
    pub fn parse(bytes: &[u8], path: &Path) -> Result<Checkpoint, CheckpointError> {
        let damaged = |what: String| CheckpointError::Damaged {
            path: path.to_path_buf(),
            what,
        };
        let magic = bytes.get(..8);
        if let Some(old) = OLDER.iter().find(|o| magic == Some(&o[..])) {
            return Err(CheckpointError::Older {
                path: path.to_path_buf(),
                format: String::from_utf8_lossy(&old[..]).into_owned(),
            });
        }
        let Some(age) = FORMATS.iter().position(|f| magic == Some(&f[..])) else {
            return Err(CheckpointError::Magic {
                path: path.to_path_buf(),
            });
        };
        let (per_camera, viewed) = (age < 1, age < 2);
        let (summed, set, sized) = (age < 3, age < 4, age < 5);
        let bytes = match summed {
            true => {
                let (fields, crc) = bytes
                    .split_last_chunk::<4>()
                    .ok_or_else(|| damaged("it ends before its checksum".into()))?;
                if crc32fast::hash(fields) != u32::from_le_bytes(*crc) {
                    return Err(damaged(
                        "its bytes do not match the checksum written with them (the file changed \
                         after it was written, or was cut short)"
                            .into(),
                    ));
                }
                fields
            }
            false => bytes,
        };
        let mut r = Reader { bytes, at: 8, path };
        let mut name = |what: &str| -> Result<String, CheckpointError> {
            let len = r.count(&format!("the {what}'s length"))?;
            String::from_utf8(r.take(len, 1, &format!("the {what}"))?.to_vec())
                .map_err(|_| damaged(format!("the {what} is not UTF-8")))
        };
        let method = name("method name")?;
        let strategy = name("strategy name")?;
        let settings = match set {
            true => name("settings")?,
            false => String::new(),
        };
        let words = r.count("words")?;
        let step = r.count("step")?;
        let steps = r.count("steps")?;
        let primitives = r.count("primitives")?;
        let adam_step = r.u64("Adam's step")?;
        let stats = r.count("statistics")?;
        let rng = r.u64("generator")?;
        let extent = u32::try_from(r.u64("extent")?)
            .map(f32::from_bits)
            .map_err(|_| damaged("the extent is not an f32".into()))?;
        let views = match sized {
            true => Some(ViewsFootprint {
                views: r.u64("training views")?,
                pixels: r.u64("training pixels")?,
            }),
            false => None,
        };
        // No views (written before the run's first step) has no pixels either.
        let views = match views {
            Some(ViewsFootprint { views: 0, pixels }) if pixels != 0 => {
                return Err(damaged(format!("{pixels} pixels in no training views")));
            }
            v => v.filter(|v| v.views > 0),
        };
        let total = primitives
            .checked_mul(words)
            .ok_or_else(|| damaged(format!("{primitives} primitives of {words} words")))?;
        let params = r.f32s(total, "the parameters")?;
        let m = r.f32s(total, "Adam's first moments")?;
        let v = r.f32s(total, "Adam's second moments")?;
        let grad2d = r.f32s(stats, "density control's gradient statistics")?;
        let seen = r
            .take(stats, 4, "density control's view counts")?
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
            .collect();
        let mut learned = |read: bool, what: &str| -> Result<Learned, CheckpointError> {
            if !read {
                return Ok(Learned::default());
            }
            let units = r.count(&format!("the {what}' count"))?;
            let words = r.count(&format!("the {what}' learned words"))?;
            let total = units
                .checked_mul(words)
                .ok_or_else(|| damaged(format!("{units} {what} of {words} words")))?;
            Ok(Learned {
                words: r.f32s(total, &format!("the {what}' learned words"))?,
                m: r.f32s(total, &format!("the {what}' first moments"))?,
                v: r.f32s(total, &format!("the {what}' second moments"))?,
                steps: (r.take(units, 8, &format!("the {what}' step counts"))?)
                    .chunks_exact(8)
                    .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
                    .collect(),
            })
        };
        let per_view = PerViewState {
            views: learned(viewed, "views")?,
            cameras: learned(per_camera, "cameras")?,
        };
        if r.at != bytes.len() {
            return Err(damaged(format!(
                "{} bytes follow the checkpoint's end",
                bytes.len() - r.at
            )));
        }
        let checkpoint = Checkpoint {
            method,
            words,
            strategy,
            settings,
            step,
            steps,
            params,
            adam: AdamState {
                step: adam_step,
                m,
                v,
            },
            grad2d,
            seen,
            rng,
            extent,
            views,
            per_view,
        };
        match checkpoint.size_defect() {
            Some(defect) => Err(damaged(defect)),
            None => Ok(checkpoint),
        }
    }
}

/// A writer that sums what passes through it.
struct Summed<'a> {
    w: &'a mut dyn Write,
    crc: crc32fast::Hasher,
}

impl Write for Summed<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.w.write(buf)?;
        self.crc.update(&buf[..n]);
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.w.flush()
    }
}

fn write_f32s(w: &mut dyn Write, values: &[f32]) -> std::io::Result<()> {
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    w.write_all(&bytes)
}

/// Reads fields off a checkpoint's bytes, refusing to read (or allocate) past their end.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
    path: &'a Path,
}

impl Reader<'_> {
    /// `count` items of `size` bytes.
    fn take(&mut self, count: usize, size: usize, what: &str) -> Result<&[u8], CheckpointError> {
        let end = count
            .checked_mul(size)
            .and_then(|n| n.checked_add(self.at))
            .filter(|end| *end <= self.bytes.len())
            .ok_or_else(|| CheckpointError::Damaged {
                path: self.path.to_path_buf(),
                what: format!("it ends before {what} (count {count})"),
            })?;
        let out = &self.bytes[self.at..end];
        self.at = end;
        Ok(out)
    }

    fn u64(&mut self, what: &str) -> Result<u64, CheckpointError> {
        let b = self.take(1, 8, what)?;
        Ok(u64::from_le_bytes(b.try_into().expect("8 bytes")))
    }

    /// A count, which must fit in memory's address range.
    fn count(&mut self, what: &str) -> Result<usize, CheckpointError> {
        let n = self.u64(what)?;
        usize::try_from(n).map_err(|_| CheckpointError::Damaged {
            path: self.path.to_path_buf(),
            what: format!("{what} is {n}"),
        })
    }

    fn f32s(&mut self, count: usize, what: &str) -> Result<Vec<f32>, CheckpointError> {
        Ok(self
            .take(count, 4, what)?
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Checkpoint {
        Checkpoint {
            method: "3dgs".into(),
            words: 2,
            strategy: "mcmc".into(),
            settings: "on black".into(),
            step: 5,
            steps: 10,
            params: vec![1.0, -2.0, 3.5, f32::MIN_POSITIVE],
            adam: AdamState {
                step: 5,
                m: vec![0.1, 0.2, 0.3, 0.4],
                v: vec![1e-9, 2e-9, 3e-9, 4e-9],
            },
            grad2d: vec![0.5, 0.25],
            seen: vec![3, 7],
            rng: u64::MAX - 3,
            extent: 4.5,
            views: Some(ViewsFootprint {
                views: 80,
                pixels: 80 * 200 * 200,
            }),
            per_view: PerViewState::default(),
        }
    }

    /// `sample()`'s file without its checksum (the fields), and `fields` with theirs.
    fn fields() -> Vec<u8> {
        let mut bytes = vec![];
        sample().write_to(&mut bytes).unwrap();
        bytes.truncate(bytes.len() - 4);
        bytes
    }

    fn summed(mut fields: Vec<u8>) -> Vec<u8> {
        let crc = crc32fast::hash(&fields);
        fields.extend(crc.to_le_bytes());
        fields
    }

    /// A state of mismatched sizes is refused by name before a byte is written.
    #[test]
    fn a_state_of_mismatched_sizes_is_not_written() {
        type Spoil = fn(&mut Checkpoint);
        let cases: [(Spoil, &str); 6] = [
            (
                |c| c.params.push(0.0),
                "5 parameter words are not whole primitives of 2 words",
            ),
            (
                |c| c.words = 0,
                "4 parameter words are not whole primitives of 0 words",
            ),
            (
                |c| c.adam.v.truncate(3),
                "Adam's moments hold 4 and 3 words, the parameters 4",
            ),
            (
                |c| c.seen.clear(),
                "density control's statistics are for 2 and 0 primitives, the parameters for 2",
            ),
            (
                |c| (c.grad2d, c.seen) = (vec![0.0], vec![1]),
                "density control's statistics are for 1 and 1 primitives, the parameters for 2",
            ),
            (|c| c.step = 11, "step 11 is past the run's 10 steps"),
        ];
        assert_eq!(sample().size_defect(), None);
        for (spoil, want) in cases {
            let mut c = sample();
            spoil(&mut c);
            assert_eq!(c.size_defect().as_deref(), Some(want));
            let mut bytes = vec![];
            let error = c.write_to(&mut bytes).unwrap_err();
            assert_eq!(error.to_string(), format!("not a run's state: {want}"));
            assert!(bytes.is_empty());
        }
    }

    #[test]
    fn a_checkpoint_survives_its_file() {
        let viewed = Checkpoint {
            per_view: PerViewState {
                views: Learned {
                    words: vec![1.0, 0.5, -0.25, 2.0],
                    m: vec![0.1, 0.2, 0.3, 0.4],
                    v: vec![1e-9, 2e-9, 3e-9, 4e-9],
                    steps: vec![3, 0],
                },
                cameras: Learned::default(),
            },
            ..sample()
        };
        let cameras = Learned {
            words: vec![0.125, -0.5, 1.0],
            m: vec![0.3, 0.2, 0.1],
            v: vec![3e-9, 2e-9, 1e-9],
            steps: vec![7],
        };
        let with_cameras = Checkpoint {
            per_view: PerViewState {
                cameras: cameras.clone(),
                ..viewed.per_view.clone()
            },
            ..sample()
        };
        let cameras_alone = Checkpoint {
            per_view: PerViewState {
                views: Learned::default(),
                cameras,
            },
            ..sample()
        };
        for c in [sample(), viewed, with_cameras, cameras_alone] {
            let mut bytes = vec![];
            c.write_to(&mut bytes).unwrap();
            assert_eq!(Checkpoint::parse(&bytes, Path::new("c.bin")).unwrap(), c);
        }
    }

    /// Checkpoints of the formats before the per-camera state (`SPLATCK7`), the per-view
    /// state (`SPLATCK6`), the checksum (`SPLATCK5`), the settings (`SPLATCK4`) and the
    /// views' footprint (`SPLATCK3`) resume, what they lack unknown or none.
    #[test]
    fn checkpoints_of_the_previous_formats_are_read() {
        let mut bytes = fields();
        // No per-camera state: its two counts, zero, end the fields; then the per-view
        // state's likewise.
        bytes.truncate(bytes.len() - 16);
        bytes[..8].copy_from_slice(b"SPLATCK7");
        assert_eq!(
            Checkpoint::parse(&summed(bytes.clone()), Path::new("c.bin")).unwrap(),
            sample()
        );
        bytes.truncate(bytes.len() - 16);
        bytes[..8].copy_from_slice(b"SPLATCK6");
        assert_eq!(
            Checkpoint::parse(&summed(bytes.clone()), Path::new("c.bin")).unwrap(),
            sample()
        );
        bytes[..8].copy_from_slice(b"SPLATCK5");
        assert_eq!(
            Checkpoint::parse(&bytes, Path::new("c.bin")).unwrap(),
            sample()
        );
        // The settings follow the two names: after the magic, "3dgs" and "mcmc".
        let settings = 8 + (8 + 4) + (8 + 4);
        bytes.drain(settings..settings + 8 + "on black".len());
        bytes[..8].copy_from_slice(b"SPLATCK4");
        let unset = Checkpoint {
            settings: String::new(),
            ..sample()
        };
        assert_eq!(
            Checkpoint::parse(&bytes, Path::new("c.bin")).unwrap(),
            unset
        );
        // The footprint follows the extent, 8 header words on.
        let at = settings + 8 * 8;
        bytes.drain(at..at + 16);
        bytes[..8].copy_from_slice(b"SPLATCK3");
        let back = Checkpoint::parse(&bytes, Path::new("c.bin")).unwrap();
        assert_eq!(
            back,
            Checkpoint {
                views: None,
                ..unset
            }
        );
    }

    /// Every truncation and every changed byte are refused with the file's name, by the
    /// magic or the checksum.
    #[test]
    fn changed_checkpoints_are_refused_by_name() {
        let mut bytes = vec![];
        sample().write_to(&mut bytes).unwrap();
        let path = Path::new("run/checkpoint.bin");
        for n in 0..bytes.len() {
            let e = Checkpoint::parse(&bytes[..n], path)
                .unwrap_err()
                .to_string();
            assert!(e.starts_with("run/checkpoint.bin "), "{e}");
        }
        for at in 0..bytes.len() {
            let mut changed = bytes.clone();
            changed[at] ^= 0x10;
            let e = Checkpoint::parse(&changed, path).unwrap_err().to_string();
            let why = if at < 8 { "not a splat" } else { "checksum" };
            assert!(
                e.starts_with("run/checkpoint.bin ") && e.contains(why),
                "{e}"
            );
        }
    }

    /// Checksummed and still wrong (written so by a fault, or by hand): trailing bytes and a
    /// count far past the file's size are refused with the file's name (no panic, no huge
    /// allocation).
    #[test]
    fn damaged_checkpoints_are_refused_by_name() {
        let bytes = fields();
        let path = Path::new("run/checkpoint.bin");
        let mut long = bytes.clone();
        long.push(0);
        let e = Checkpoint::parse(&summed(long), path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("1 bytes follow"), "{e}");
        let mut huge = bytes.clone();
        // The primitive count (after magic, the names' and settings' lengths and texts, words,
        // step, steps).
        let names = 8 + (8 + 4) + (8 + 4) + (8 + 8);
        let at = names + 3 * 8;
        huge[at..at + 8].copy_from_slice(&(1u64 << 60).to_le_bytes());
        let e = Checkpoint::parse(&summed(huge), path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("damaged") && !e.contains("checksum"), "{e}");
        // Pixels in no views (the views' count follows the extent, after 8 header words).
        let mut pixels = bytes.clone();
        let at = names + 8 * 8;
        pixels[at..at + 8].copy_from_slice(&0u64.to_le_bytes());
        let e = Checkpoint::parse(&summed(pixels), path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("pixels in no training views"), "{e}");
        // A state no run has (`size_defect`): a step past the run's end (the step follows
        // the words).
        let mut late = bytes.clone();
        let at = names + 8;
        late[at..at + 8].copy_from_slice(&11u64.to_le_bytes());
        let e = Checkpoint::parse(&summed(late), path)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("damaged: step 11 is past the run's 10 steps"),
            "{e}"
        );
        let e = Checkpoint::parse(b"PLY\n....", path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a splat checkpoint"), "{e}");
        let e = Checkpoint::parse(b"SPLATCK1.......", path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("earlier splat (format SPLATCK1)"), "{e}");
        #[cfg(unix)]
        {
            let e = Checkpoint::read(Path::new("/dev/zero"))
                .unwrap_err()
                .to_string();
            assert!(e.contains("not a regular file"), "{e}");
        }
    }
}
