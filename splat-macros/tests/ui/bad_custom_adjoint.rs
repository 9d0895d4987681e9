use splat_macros::splat_functions;

#[splat_functions]
mod m {
    use splat_runtime::prelude::*;

    #[adjoint(g_adjoint)]
    fn g(x: f32) -> f32 {
        x * x
    }

    fn g_adjoint(x: f32) -> f32 {
        2.0 * x
    }

    pub fn f(x: f32) -> f32 {
        g(x)
    }
}

fn main() {}
