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
    /// seed's splat-subgroup cohesion, which nothing guarantees), one atomic per (subgroup,
    /// word) from its first lane that is not a helper; elsewhere one per fragment.
    Subgroup,
    /// [`FragmentReduction::Subgroup`] where the subgroup is cohesive, the quads' sums
    /// elsewhere: the seed's hybrid, never more atomics than either.
    Hybrid,
}

impl FragmentReduction {
    pub const ALL: [FragmentReduction; 4] = [Self::None, Self::Quad, Self::Subgroup, Self::Hybrid];

    /// [`FragmentReduction::Hybrid`] where `gpu` has subgroup operations in fragment shaders,
    /// else [`FragmentReduction::None`].
    pub fn default_for(gpu: &Gpu) -> FragmentReduction {
        match gpu.subgroups {
            true => Self::Hybrid,
            false => Self::None,
        }
    }

    /// What it does, for the shader's header.
    pub fn note(self) -> &'static str {
        match self {
            Self::None => "one atomic per fragment and nonzero word.",
            Self::Quad => {
                "each word summed over the fragment's 2x2 quad first, one atomic per quad and nonzero word."
            }
            Self::Subgroup => {
                "each word summed over the subgroup where all its lanes draw one primitive, one atomic per fragment elsewhere."
            }
            Self::Hybrid => {
                "each word summed over the subgroup where all its lanes draw one primitive, over the 2x2 quad elsewhere."
            }
        }
    }
}

/// [`scatter`] for a fragment of the hardware backward (`helper` set in helper invocations,
/// whose words are zero; `prim` its primitive), its words summed as `reduce` says. Written at
/// the top level of the shader, where every lane that started is still running.
pub fn scatter_fragments(reduce: FragmentReduction, words: usize) -> String {
    let add = |indent: &str, k: usize, v: &str, who: &str| {
        format!(
            "{indent}if ({who}{v} != 0.0) {{
{indent}    add_grad(prim * NG + {k}u, {v});
{indent}    my_issued++;
{indent}}}
"
        )
    };
    let each_fragment =
        |indent: &str| -> String { (0..words).map(|k| add(indent, k, &word(k), "")).collect() };
    let quads = |indent: &str| -> String {
        // A lane's place in its 2x2 quad, by the parity of its pixel.
        let mut s = format!(
            "{indent}let quad_lane = (u32(px) & 1u) | ((u32(py) & 1u) << 1u);
{indent}var lanes = select(0u, 1u << quad_lane, !helper);
{indent}lanes = lanes | quadSwapX(lanes);
{indent}lanes = lanes | quadSwapY(lanes);
{indent}let quad_first = firstTrailingBit(lanes) == quad_lane;
"
        );
        for k in 0..words {
            let _ = write!(
                s,
                "{indent}let pair{k} = {w} + quadSwapX({w});
{indent}let quad{k} = pair{k} + quadSwapY(pair{k});
",
                w = word(k)
            );
            s += &add(indent, k, &format!("quad{k}"), "quad_first && ");
        }
        s
    };
    let subgroups = |otherwise: String| -> String {
        // `cohesive` is the same in every lane, so each branch runs with the whole subgroup.
        let mut s = "    let cohesive = subgroupAll(subgroupBroadcastFirst(prim) == prim);
    if (cohesive) {
        let subgroup_first = !helper && subgroupExclusiveAdd(select(1u, 0u, helper)) == 0u;
"
        .to_string();
        for k in 0..words {
            let _ = writeln!(s, "        let sub{k} = subgroupAdd({});", word(k));
            s += &add("        ", k, &format!("sub{k}"), "subgroup_first && ");
        }
        s + "    } else {
" + &otherwise
            + "    }
"
    };
    match reduce {
        FragmentReduction::None => each_fragment("    "),
        FragmentReduction::Quad => quads("    "),
        FragmentReduction::Subgroup => subgroups(each_fragment("        ")),
        FragmentReduction::Hybrid => subgroups(quads("        ")),
    }
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
    let add = |indent: &str, k: &str, v: &str| {
        format!(
            "{indent}if ({v} != 0.0) {{
{indent}    add_grad(prim * NG + {k}, {v});
{indent}    my_issued++;
{indent}}}
"
        )
    };
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
        for reduce in FragmentReduction::ALL {
            let s = scatter_fragments(reduce, 10);
            // The subgroup's sums, and what a subgroup that is not cohesive does instead.
            let branches = match reduce {
                FragmentReduction::None | FragmentReduction::Quad => 1,
                FragmentReduction::Subgroup | FragmentReduction::Hybrid => 2,
            };
            for k in 0..10 {
                let adds = s.matches(&format!("prim * NG + {k}u,")).count();
                assert_eq!(adds, branches, "{reduce:?}: {s}");
            }
            assert_eq!(
                s.contains("quadSwapX"),
                reduce == FragmentReduction::Quad || reduce == FragmentReduction::Hybrid
            );
        }
    }
}
