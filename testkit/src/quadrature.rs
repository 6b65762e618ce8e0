//! Gauss-Legendre quadrature, for integrating pdfs over bins and over the sphere.

/// Nodes and weights of an n-point Gauss-Legendre rule on [-1, 1].
#[derive(Clone, Debug)]
pub struct GaussLegendre {
    nodes: Vec<f64>,
    weights: Vec<f64>,
}

impl GaussLegendre {
    /// Computes the rule by Newton iteration on the Legendre polynomial's roots.
    pub fn new(n: usize) -> Self {
        assert!(n >= 1);
        let mut nodes = vec![0.0; n];
        let mut weights = vec![0.0; n];
        for i in 0..n.div_ceil(2) {
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut dp = 0.0;
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                    p0 = p1;
                    p1 = p2;
                }
                let p = if n == 1 { x } else { p1 };
                let pm1 = if n == 1 { 1.0 } else { p0 };
                dp = n as f64 * (x * p - pm1) / (x * x - 1.0);
                let dx = p / dp;
                x -= dx;
                if dx.abs() < 1e-15 {
                    break;
                }
            }
            if n == 1 {
                nodes[0] = 0.0;
                weights[0] = 2.0;
                break;
            }
            nodes[i] = -x;
            nodes[n - 1 - i] = x;
            let w = 2.0 / ((1.0 - x * x) * dp * dp);
            weights[i] = w;
            weights[n - 1 - i] = w;
        }
        Self { nodes, weights }
    }

    /// Integral of `f` over [a, b].
    pub fn integrate(&self, a: f64, b: f64, f: impl Fn(f64) -> f64) -> f64 {
        let (h, m) = (0.5 * (b - a), 0.5 * (a + b));
        self.nodes.iter().zip(&self.weights).map(|(&x, &w)| w * f(m + h * x)).sum::<f64>() * h
    }

    /// Integral of `f` over the rectangle [a0, a1] x [b0, b1].
    pub fn integrate_2d(
        &self,
        a0: f64,
        a1: f64,
        b0: f64,
        b1: f64,
        f: impl Fn(f64, f64) -> f64,
    ) -> f64 {
        self.integrate(a0, a1, |a| self.integrate(b0, b1, |b| f(a, b)))
    }
}

/// Integral of `f` over [a, b] split into `pieces` equal parts, each with an 8-point rule.
pub fn integrate_1d(f: &dyn Fn(f64) -> f64, a: f64, b: f64, pieces: usize) -> f64 {
    let gl = GaussLegendre::new(8);
    let h = (b - a) / pieces as f64;
    (0..pieces).map(|i| gl.integrate(a + h * i as f64, a + h * (i + 1) as f64, f)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_for_polynomials() {
        let gl = GaussLegendre::new(5);
        // A 5-point rule is exact up to degree 9.
        let v = gl.integrate(0.0, 2.0, |x| x.powi(9) - 3.0 * x.powi(4));
        assert!((v - (2f64.powi(10) / 10.0 - 3.0 * 2f64.powi(5) / 5.0)).abs() < 1e-10);
        assert!(
            (integrate_1d(&|x: f64| x.sin(), 0.0, std::f64::consts::PI, 4) - 2.0).abs() < 1e-12
        );
    }
}
