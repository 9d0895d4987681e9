use splat_macros::splat_functions;

#[splat_functions]
pub mod basic {
    use splat_runtime::prelude::*;

    pub fn poly(x: f32, y: f32) -> f32 {
        let a = x * x + 3.0 * y;
        a / (1.0 + y * y) - x
    }

    pub fn vec_ops(a: Vec3, b: Vec3) -> Vec3 {
        let c = a.cross(b);
        c.normalize() * a.dot(b) + b.length()
    }

    pub fn branchy(x: f32, y: f32) -> f32 {
        let mut acc = x;
        if x > y {
            acc = acc * y;
        } else {
            acc = acc + y.exp();
        }
        for i in 0..3 {
            acc = acc * 0.5 + (i as f32) * x;
        }
        select(x > 0.0, x.ln() * y, acc)
    }
}
