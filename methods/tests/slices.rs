//! A scene cut into slices, each projected on its own and the visible records rendered
//! together (what sharded training does across processes), is the whole scene: the same frame
//! and, sent back slice by slice, the same gradients, bit for bit.

use crate::common::{camera, spread_gaussians};
use splat_methods::gs3d::Method;
use splat_runtime::pipeline::{
    backward, backward_blend, project_adjoints, project_visible, render_for_backward,
    render_records_for_backward,
};
use splat_runtime::{Flat, FrameGrad, RenderOptions};

#[test]
fn slices_rendered_together_are_the_whole_scene_bit_for_bit() {
    let cam = camera(48, 40);
    let mut scene = spread_gaussians(&cam, 300, 7);
    // Some behind the camera: projected, never sent.
    for g in scene.iter_mut().step_by(7) {
        g.mean.z = -g.mean.z;
    }
    let opts = RenderOptions {
        tile_size: 8,
        alpha: true,
        ..Default::default()
    };
    let (whole, state) = render_for_backward::<Method>(&scene, &cam, &opts).unwrap();
    let mut rng = fastrand::Rng::with_seed(3);
    let pixels = (cam.size.x * cam.size.y) as usize;
    let grad = FrameGrad {
        color: (0..3 * pixels).map(|_| rng.f32() - 0.5).collect(),
        alpha: Some((0..pixels).map(|_| rng.f32() - 0.5).collect()),
        depth: None,
    };
    let want = backward::<Method>(&state, &scene, &cam, &grad).unwrap();

    for cuts in [vec![0, 300], vec![0, 120, 300], vec![0, 1, 150, 151, 300]] {
        let slices: Vec<_> = cuts.windows(2).map(|w| &scene[w[0]..w[1]]).collect();
        let sent: Vec<_> = (slices.iter())
            .map(|s| project_visible::<Method>(s, &cam, &opts).unwrap())
            .collect();
        let records = sent
            .iter()
            .flat_map(|v| v.records.iter().copied())
            .collect();
        let (frame, state) = render_records_for_backward::<Method>(records, &cam, &opts).unwrap();
        assert_eq!(frame.color.data, whole.color.data, "cut at {cuts:?}");
        assert_eq!(frame.alpha, whole.alpha);
        assert!(sent.iter().map(|v| v.index.len()).sum::<usize>() < scene.len());

        // Each record's gradients go back to its slice, whose primitives take `project`'s
        // adjoint there.
        let blended = backward_blend::<Method>(&state, &grad).unwrap();
        let words = <<Method as splat_runtime::SplatMethod>::Shade as Flat>::LEN;
        let mut at = 0;
        let mut got = vec![];
        for (slice, visible) in slices.iter().zip(&sent) {
            let mut shade = vec![0.0; slice.len() * words];
            let mut depth = vec![0.0; slice.len()];
            for &i in &visible.index {
                let i = i as usize;
                shade[i * words..(i + 1) * words]
                    .copy_from_slice(&blended.shade[at * words..(at + 1) * words]);
                depth[i] = blended.depth[at];
                at += 1;
            }
            let (params, _) =
                project_adjoints::<Method>(slice, &cam, &shade, &depth, state.gradients);
            got.extend(params);
        }
        assert_eq!(at, blended.depth.len(), "every record went back");
        assert!(got == want.params, "cut at {cuts:?}");
    }
}
