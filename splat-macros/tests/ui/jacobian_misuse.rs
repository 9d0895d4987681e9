use splat_macros::splat_functions;

#[splat_functions]
mod m {
    use splat_runtime::prelude::*;

    #[adjoint(soft_adjoint)]
    fn soft(x: f32) -> f32 {
        (x * x + 0.01).sqrt()
    }

    fn soft_adjoint(x: f32, d_out: f32) -> f32 {
        d_out * x / (x * x + 0.01).sqrt()
    }

    pub fn at_an_integer(n: u32) -> f32 {
        let (v, _) = jacobian(|p| p * 2.0, n);
        v
    }

    pub fn to_a_matrix(x: Vec2) -> f32 {
        let (m, _) = jacobian(|p| Mat2::from_cols(p, p), x);
        m.x_axis.x
    }

    pub fn two_arguments(x: f32) -> f32 {
        let (v, _) = jacobian(|p, q| p * q, x);
        v
    }

    pub fn through_a_custom_adjoint(x: f32) -> f32 {
        let (_, j) = jacobian(|p| soft(p), x);
        j[0]
    }

    pub fn result_not_as_written(x: f32) -> f32 {
        let (v, _) = jacobian(|p| -> f32 { Vec2::new(p, p) }, x);
        v.x
    }

    pub fn assigns_outside(x: f32) -> f32 {
        let mut total = 0.0;
        let (v, _) = jacobian(
            |p| {
                total = p;
                p * 2.0
            },
            x,
        );
        v + total
    }
}

fn main() {}
