//! How the backward blend adds one list entry's gradient words to its primitive's sums,
//! written out word by word.
//!
//! The words live in scalars `g0 .. g{NG-1}` (not an array walked by a loop): a loop over a
//! per-invocation array inside the blend's hottest loop keeps the array in local memory
//! unless the driver unrolls it, and naga's loop bounding (a 64-bit counter per loop that
//! persists across entries) stands in the way of unrolling; around `subgroupAdd`, a loop the
//! driver cannot prove uniform also costs a reconvergence per word.

use super::Gpu;
use std::fmt::Write;

/// Where the backward blend sums an entry's gradient over pixels before its global atomics.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Reduction {
    /// No reduction: one atomic per (pixel, entry, gradient word), the baseline.
    None,
    /// `subgroupAdd` over each subgroup (no barrier): one atomic per (subgroup, entry, word).
    Subgroup,
    /// A tree in workgroup memory: one atomic per (tile, entry, word), at the price of a
    /// barrier per level.
    Workgroup,
}

/// How the backward blend adds its gradients to global memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Accumulation {
    pub reduce: Reduction,
    /// `atomicAdd` on f32 (`SHADER_FLOAT32_ATOMIC`); otherwise a compare-exchange loop on u32.
    pub float_atomics: bool,
}

impl Accumulation {
    /// Subgroup reduction where the adapter has subgroups (else workgroup reduction), with
    /// f32 atomics where it has them (else compare-exchange). On the H200 the subgroup
    /// reduction is the fastest and the two atomics tie after it (200k Gaussians at
    /// 1920x1080, the gpu bench's sweep: 10.4 ms with f32 `atomicAdd`, 9.9 with
    /// compare-exchange, against 18.9 / 366 without a reduction and 56.0 / 33.9 with the
    /// workgroup's).
    pub fn default_for(gpu: &Gpu) -> Accumulation {
        Accumulation {
            reduce: if gpu.subgroups {
                Reduction::Subgroup
            } else {
                Reduction::Workgroup
            },
            float_atomics: gpu.float_atomics,
        }
    }
}

/// Where the hardware backward (`raster::backward`) sums a fragment's gradient before its
/// global atomics (the seed's Table I compares them). Every way but [`FragmentReduction::None`]
/// needs quad and subgroup operations in fragment shaders ([`Gpu::subgroups`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FragmentReduction {
    /// One atomic per (fragment, word): the seed's baseline.
    None,
    /// Summed over each 2x2 quad (all one primitive's: a quad's four lanes come from one
    /// triangle) by two swaps, then one atomic per (quad, word) from its first lane that is
    /// not a helper invocation (helpers' words are zero).
    Quad,
    /// Summed over the subgroup by `subgroupAdd` where all its lanes draw one primitive (the
    /// seed's splat-subgroup cohesion, which nothing guarantees) and at least `min_lanes` of
    /// them blend (the seed's balancing threshold X), one atomic per (subgroup, word) from its
    /// first lane that is not a helper; elsewhere one per fragment.
    Subgroup { min_lanes: u32 },
    /// [`FragmentReduction::Subgroup`] where it sums the subgroup, the quads' sums elsewhere:
    /// the seed's hybrid, never more atomics than either.
    Hybrid { min_lanes: u32 },
}

impl FragmentReduction {
    /// Each way, the subgroup's without a threshold.
    pub const ALL: [FragmentReduction; 4] = [
        Self::None,
        Self::Quad,
        Self::Subgroup { min_lanes: 0 },
        Self::Hybrid { min_lanes: 0 },
    ];

    /// [`FragmentReduction::Hybrid`] without a threshold where `gpu` has subgroup operations
    /// in fragment shaders, else [`FragmentReduction::None`].
    pub fn default_for(gpu: &Gpu) -> FragmentReduction {
        match gpu.subgroups {
            true => Self::Hybrid { min_lanes: 0 },
            false => Self::None,
        }
    }

    /// What it does, for the shader's header.
    pub fn shader_note(self) -> String {
        let cohesive = |min_lanes| match min_lanes {
            0 => "where all its lanes draw one primitive".to_string(),
            n => format!("where all its lanes draw one primitive and {n} or more blend"),
        };
        match self {
            Self::None => "one atomic per fragment and nonzero word.".into(),
            Self::Quad => "each word summed over the fragment's 2x2 quad first, one atomic per quad and nonzero word.".into(),
            Self::Subgroup { min_lanes } => format!(
                "each word summed over the subgroup {}, one atomic per fragment elsewhere.",
                cohesive(min_lanes)
            ),
            Self::Hybrid { min_lanes } => format!(
                "each word summed over the subgroup {}, over the 2x2 quad elsewhere.",
                cohesive(min_lanes)
            ),
        }
    }
}

/// [`scatter`] for a fragment of the hardware backward (`helper` set in helper invocations,
/// whose words are zero; `live` where the fragment blends; `prim` its primitive), its words
/// summed as `reduce` says. Written at the top level of the shader, where every lane that
/// started is still running: every quad and subgroup operation runs there, unconditionally
/// (a helper invocation need not take part in subgroup operations, so its view of the
/// subgroup may differ: only the adds, which helpers never make, depend on it).
pub fn scatter_fragments(reduce: FragmentReduction, words: usize) -> String {
    let mut s = String::new();
    let (quads, subgroups) = match reduce {
        FragmentReduction::None => (false, None),
        FragmentReduction::Quad => (true, None),
        FragmentReduction::Subgroup { min_lanes } => (false, Some(min_lanes)),
        FragmentReduction::Hybrid { min_lanes } => (true, Some(min_lanes)),
    };
    if quads {
        // A lane's place in its 2x2 quad, by the parity of its pixel.
        s += "    let quad_lane = (u32(px) & 1u) | ((u32(py) & 1u) << 1u);
    var lanes = select(0u, 1u << quad_lane, !helper);
    lanes = lanes | quadSwapX(lanes);
    lanes = lanes | quadSwapY(lanes);
    let quad_first = firstTrailingBit(lanes) == quad_lane;
";
        for k in 0..words {
            let w = word(k);
            let _ = writeln!(s, "    let pair{k} = {w} + quadSwapX({w});");
            let _ = writeln!(s, "    let quad{k} = pair{k} + quadSwapY(pair{k});");
        }
    }
    if let Some(min_lanes) = subgroups {
        s += "    var cohesive = subgroupAll(subgroupBroadcastFirst(prim) == prim);\n";
        if min_lanes > 0 {
            s += "    let blending = subgroupAdd(select(0u, 1u, live));\n";
            let _ = writeln!(s, "    cohesive = cohesive && blending >= {min_lanes}u;");
        }
        s += "    let rank = subgroupExclusiveAdd(select(1u, 0u, helper));
    let subgroup_first = !helper && rank == 0u;
";
        for k in 0..words {
            let _ = writeln!(s, "    let sub{k} = subgroupAdd({});", word(k));
        }
    }
    let adds = |indent: &str, sum: &dyn Fn(usize) -> (String, &'static str)| -> String {
        (0..words)
            .map(|k| {
                let (v, guard) = sum(k);
                add_word(indent, format!("{k}u"), &v, guard)
            })
            .collect()
    };
    let fragment = |k: usize| (word(k), "");
    let quad = |k: usize| (format!("quad{k}"), "quad_first && ");
    let subgroup = |k: usize| (format!("sub{k}"), "subgroup_first && ");
    let otherwise = |indent| match quads {
        true => adds(indent, &quad),
        false => adds(indent, &fragment),
    };
    match subgroups {
        None => s += &otherwise("    "),
        Some(_) => {
            s += "    if (cohesive) {\n";
            s += &adds("        ", &subgroup);
            s += "    } else {\n";
            s += &otherwise("        ");
            s += "    }\n";
        }
    }
    s
}

/// Adds `v` to word `k` of primitive `prim`'s sums through `add_grad` where `guard` (a WGSL
/// condition and `&&`, or nothing) holds and `v` is not zero, counting it in `my_issued`.
fn add_word(indent: &str, k: impl std::fmt::Display, v: &str, guard: &str) -> String {
    format!(
        "{indent}if ({guard}{v} != 0.0) {{
{indent}    add_grad(prim * NG + {k}, {v});
{indent}    my_issued++;
{indent}}}
"
    )
}

/// The scalar holding gradient word `k` of the entry.
pub fn word(k: usize) -> String {
    format!("g{k}")
}

/// Declares the `words` gradient scalars of one entry, zeroed.
pub fn declare(words: usize) -> String {
    (0..words)
        .map(|k| format!("            var {} = 0.0;\n", word(k)))
        .collect()
}

/// Adds the `words` scalars to the sums of primitive `prim` (at `prim * NG + k`) through
/// `add_grad`, counting each global add in `my_issued`; `reduce` says what is summed first.
/// `words_per_round` is how many words one workgroup reduction round sums (its `red` holds
/// `words_per_round * WG` floats).
pub fn scatter(reduce: Reduction, words: usize, words_per_round: usize) -> String {
    let add = |indent: &str, k: &str, v: &str| add_word(indent, k, v, "");
    let mut s = String::new();
    match reduce {
        Reduction::None => {
            for k in 0..words {
                s += &add("            ", &format!("{k}u"), &word(k));
            }
        }
        Reduction::Subgroup => {
            // A subgroup none of whose pixels the entry reaches skips its reductions.
            s += "            if (subgroupAny(hit)) {\n";
            for k in 0..words {
                let _ = writeln!(s, "                let v{k} = subgroupAdd({});", word(k));
                s += "                if (lane == 0u) {\n";
                s += &add("                    ", &format!("{k}u"), &format!("v{k}"));
                s += "                }\n";
            }
            s += "            }\n";
        }
        Reduction::Workgroup => {
            for first in (0..words).step_by(words_per_round.max(1)) {
                let n = words_per_round.min(words - first);
                for k in 0..n {
                    let _ = writeln!(s, "            red[{k}u * WG + lid] = {};", word(first + k));
                }
                s += "            workgroupBarrier();
            for (var half = WG / 2u; half > 0u; half >>= 1u) {
                if (lid < half) {\n";
                for k in 0..n {
                    let _ = writeln!(
                        s,
                        "                    red[{k}u * WG + lid] += red[{k}u * WG + lid + half];"
                    );
                }
                s += "                }
                workgroupBarrier();
            }\n";
                let _ = writeln!(s, "            if (lid < {n}u) {{");
                s += "                let v = red[lid * WG];\n";
                s += &add("                ", &format!("{first}u + lid"), "v");
                s += "            }\n            workgroupBarrier();\n";
            }
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_word_is_added_once_in_each_reduction() {
        for (reduce, round) in [
            (Reduction::None, 1),
            (Reduction::Subgroup, 1),
            (Reduction::Workgroup, 4),
            (Reduction::Workgroup, 3),
        ] {
            let s = scatter(reduce, 10, round);
            // No loop walks the words: the only loop left is the workgroup tree's.
            assert_eq!(
                s.matches("for (").count(),
                10usize.div_ceil(round) * (reduce == Reduction::Workgroup) as usize
            );
            match reduce {
                Reduction::Workgroup => {
                    // Rounds of `round` words cover 0..10, each word read once.
                    for k in 0..10 {
                        assert_eq!(s.matches(&format!("= g{k};")).count(), 1, "{s}");
                    }
                    assert_eq!(s.matches("add_grad(").count(), 10usize.div_ceil(round));
                }
                _ => {
                    for k in 0..10 {
                        assert_eq!(s.matches(&format!("prim * NG + {k}u,")).count(), 1, "{s}");
                    }
                }
            }
        }
    }

    #[test]
    fn every_fragment_reduction_adds_each_word_once_per_branch() {
        let thresholds = [
            FragmentReduction::Subgroup { min_lanes: 8 },
            FragmentReduction::Hybrid { min_lanes: 8 },
        ];
        for reduce in FragmentReduction::ALL.into_iter().chain(thresholds) {
            let s = scatter_fragments(reduce, 10);
            // The subgroup's sums, and what a subgroup that is not cohesive does instead.
            let (quads, branches) = match reduce {
                FragmentReduction::None => (false, 1),
                FragmentReduction::Quad => (true, 1),
                FragmentReduction::Subgroup { .. } => (false, 2),
                FragmentReduction::Hybrid { .. } => (true, 2),
            };
            for k in 0..10 {
                let adds = s.matches(&format!("prim * NG + {k}u,")).count();
                assert_eq!(adds, branches, "{reduce:?}: {s}");
            }
            assert_eq!(s.contains("quadSwapX"), quads, "{reduce:?}");
            // Every quad and subgroup operation at the top level, before any branch.
            let branch = s.find("if (").unwrap_or(s.len());
            let ops = ["quadSwapX(", "quadSwapY(", "subgroupAll(", "subgroupAdd("];
            for op in ops
                .into_iter()
                .chain(["subgroupBroadcastFirst(", "subgroupExclusiveAdd("])
            {
                assert!(
                    s.rfind(op).is_none_or(|at| at < branch),
                    "{reduce:?}: {op} in a branch: {s}"
                );
            }
            let counts_lanes = matches!(
                reduce,
                FragmentReduction::Subgroup { min_lanes: 8 }
                    | FragmentReduction::Hybrid { min_lanes: 8 }
            );
            assert_eq!(s.contains("blending >= 8u"), counts_lanes, "{reduce:?}");
        }
    }
}
