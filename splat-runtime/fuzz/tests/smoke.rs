//! CI's short fuzz run: every target reads its seed corpus (`valid-*` seeds are accepted,
//! `bad-*` ones refused, so the harness is known to reach the reader) and deterministic
//! mutations of each seed, under an allocator that counts. No input may panic, nor hold more
//! than `ALLOWANCE` plus `Target::most_per_byte` times its size at once: a header that claims more than the
//! file holds is refused before anything is allocated for it. The coverage-guided runs are
//! AFL++'s (docs/testing.md).

use splat_fuzz::{SEPARATOR, Scratch, Target};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Mutations of each seed.
const MUTANTS: usize = 1500;
/// What a reader may allocate whatever the input: buffers, a picture's decoder, rayon's pool.
const ALLOWANCE: usize = 2 << 20;

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let live = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(live, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        unsafe { System.dealloc(p, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }

    unsafe fn realloc(&self, p: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let q = unsafe { System.realloc(p, layout, new_size) };
        if !q.is_null() {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
            let live = LIVE.fetch_add(new_size, Ordering::Relaxed) + new_size;
            PEAK.fetch_max(live, Ordering::Relaxed);
        }
        q
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Runs `target` on `input`, asserting its allocations stay in bounds; whether it accepted.
fn run(target: Target, scratch: &Scratch, input: &[u8], what: &str) -> bool {
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let accepted = target.run(scratch, input);
    let held = PEAK.load(Ordering::Relaxed).saturating_sub(base);
    let bound = ALLOWANCE + target.most_per_byte() * input.len();
    assert!(
        held <= bound,
        "{} on {what}: held {held} bytes at once for a {}-byte input (bound {bound})",
        target.name(),
        input.len()
    );
    accepted
}

/// Values that break readers: limits of the integer types, overflowing and special floats.
const NUMBERS: &[&str] = &[
    "0",
    "-1",
    "4294967296",
    "18446744073709551616",
    "99999999999999999999999",
    "1e309",
    "-1e-320",
    "NaN",
    "inf",
];
const WORDS: &[u64] = &[
    0,
    u64::MAX,
    1 << 62,
    i32::MAX as u64,
    0x7ff8_0000_0000_0000, // f64 NaN
    0x7ff0_0000_0000_0000, // f64 infinity
    0xffff_ffff,
];

/// One to four random edits of `seed`: bit flips, special bytes, cut, doubled or dropped
/// ranges, numbers in text replaced by `NUMBERS`, 8-byte words by `WORDS`, the file
/// separator dropped or doubled.
fn mutate(rng: &mut fastrand::Rng, seed: &[u8]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..rng.usize(1..=4) {
        let n = b.len().max(1);
        match rng.u8(0..8) {
            0 if !b.is_empty() => b[rng.usize(..n)] ^= 1 << rng.u8(0..8),
            1 if !b.is_empty() => {
                b[rng.usize(..n)] = *rng.choice(b"\0\xff\x7f\x80-9\"\n ").unwrap()
            }
            2 => b.truncate(rng.usize(..n)),
            3 if !b.is_empty() => {
                let at = rng.usize(..n);
                let end = (at + rng.usize(1..64)).min(b.len());
                let piece = b[at..end].to_vec();
                let to = rng.usize(..=b.len());
                b.splice(to..to, piece);
            }
            4 if !b.is_empty() => {
                let at = rng.usize(..n);
                let end = (at + rng.usize(1..16)).min(b.len());
                b.drain(at..end);
            }
            5 => {
                let digits: Vec<usize> = (0..b.len()).filter(|&i| b[i].is_ascii_digit()).collect();
                if let Some(&start) = rng.choice(&digits) {
                    let end = (start..b.len())
                        .find(|&i| !(b[i].is_ascii_digit() || b[i] == b'.'))
                        .unwrap_or(b.len());
                    b.splice(start..end, rng.choice(NUMBERS).unwrap().bytes());
                }
            }
            6 if b.len() >= 8 => {
                let at = rng.usize(..=b.len() - 8) & !3;
                b[at..at + 8].copy_from_slice(&rng.choice(WORDS).unwrap().to_le_bytes());
            }
            _ => {
                if let Some(at) = b.windows(SEPARATOR.len()).position(|w| w == SEPARATOR) {
                    match rng.bool() {
                        true => drop(b.drain(at..at + SEPARATOR.len())),
                        false => drop(b.splice(at..at, SEPARATOR.iter().copied())),
                    }
                }
            }
        }
    }
    b
}

#[test]
fn no_reader_panics_or_overallocates_on_the_corpus_and_its_mutations() {
    let scratch = Scratch::new().expect("a scratch folder");
    let mut rng = fastrand::Rng::with_seed(2026);
    for target in Target::ALL {
        let mut seeds: Vec<_> = std::fs::read_dir(target.corpus())
            .unwrap_or_else(|e| panic!("{}: {e}", target.corpus().display()))
            .map(|entry| entry.unwrap().path())
            .collect();
        seeds.sort();
        assert!(!seeds.is_empty(), "{}: no seeds", target.name());
        let (mut runs, mut accepted) = (0, 0);
        for path in seeds {
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            let seed = std::fs::read(&path).unwrap();
            let ok = run(target, &scratch, &seed, &name);
            assert_eq!(
                ok,
                name.starts_with("valid-"),
                "{}: seed {name} should be {}",
                target.name(),
                if name.starts_with("valid-") {
                    "accepted"
                } else {
                    "refused"
                }
            );
            for k in 0..MUTANTS {
                let input = mutate(&mut rng, &seed);
                accepted +=
                    run(target, &scratch, &input, &format!("mutant {k} of {name}")) as usize;
                runs += 1;
            }
        }
        println!("{}: {runs} mutants, {accepted} accepted", target.name());
    }
}
