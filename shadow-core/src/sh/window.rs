//! Windowing of truncated SH expansions by σ-factors (see [`Window`]).

use std::f64::consts::PI;

use super::{ShOrder, ShRgb, Zonal};

/// σ-factors that scale band l of an SH expansion before it is used, to
/// tame the ringing of truncation (Sloan, "Stupid Spherical Harmonics (SH)
/// Tricks", GDC 2008, "Windowing").
///
/// Cut off after n bands, the expansion of a small bright source (a sun)
/// overshoots beside it and goes negative further out (the Gibbs
/// phenomenon); a method that dots that lighting with a transfer vector
/// then returns more light than arrives at some receivers. A window
/// multiplies band l by σ_l, falling from σ_0 = 1 toward 0 at the cut-off,
/// which is a convolution with a smooth zonal kernel: the ringing shrinks,
/// and the lighting is blurred by about the width of one band more. With
/// w = n, the window's width in bands:
///
/// ```text
/// Hanning: σ_l = (1 + cos(π l / w)) / 2
/// Lanczos: σ_l = sin(π l / w) / (π l / w)      (σ_0 = 1)
/// ```
///
/// Hanning falls faster (more blur, less ringing); Lanczos keeps more of the
/// higher bands. Windowing the lighting or the transfer gives the same
/// product, since band l of both meets only band l of the other.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[non_exhaustive]
pub enum Window {
    /// The truncated expansion as it is.
    #[default]
    None,
    Hanning,
    Lanczos,
}

impl Window {
    /// Every window, in a fixed order.
    pub const ALL: [Window; 3] = [Window::None, Window::Hanning, Window::Lanczos];

    /// σ_l for band `l` of an expansion of `order`.
    pub fn factor(self, l: usize, order: ShOrder) -> f32 {
        let x = PI * l as f64 / order.bands() as f64;
        let sigma = match self {
            Window::None => 1.0,
            Window::Hanning => (1.0 + x.cos()) / 2.0,
            Window::Lanczos if l == 0 => 1.0,
            Window::Lanczos => x.sin() / x,
        };
        sigma as f32
    }

    /// The window as a zonal kernel of `order`: its eigenvalues are the
    /// σ-factors.
    pub fn kernel(self, order: ShOrder) -> Zonal {
        let factors = (0..order.bands()).map(|l| self.factor(l, order)).collect();
        Zonal::from_eigenvalues(order, factors)
    }

    /// `lighting` with band l scaled by σ_l.
    pub fn apply(self, lighting: &ShRgb) -> ShRgb {
        match self {
            Window::None => lighting.clone(),
            _ => lighting.convolve(&self.kernel(lighting.order())),
        }
    }

    /// A short lower-case name: `none`, `hanning`, `lanczos`.
    pub fn name(self) -> &'static str {
        match self {
            Window::None => "none",
            Window::Hanning => "hanning",
            Window::Lanczos => "lanczos",
        }
    }

    /// The window named by [`Window::name`].
    pub fn from_name(name: &str) -> Option<Window> {
        Window::ALL.into_iter().find(|w| w.name() == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Environment;
    use crate::sh::project_environment;
    use approx::assert_relative_eq;
    use glam::Vec3;

    fn order(n: u32) -> ShOrder {
        ShOrder::new(n).unwrap()
    }

    #[test]
    fn factors_start_at_one_and_fall() {
        for window in [Window::Hanning, Window::Lanczos] {
            for n in 1..=9 {
                let o = order(n);
                assert_eq!(window.factor(0, o), 1.0);
                let factors: Vec<f32> = (0..n as usize).map(|l| window.factor(l, o)).collect();
                assert!(factors.windows(2).all(|f| f[1] < f[0]), "{factors:?}");
                assert!(factors.iter().all(|&f| f > 0.0), "{factors:?}");
            }
        }
        // Hanning at order 5: (1 + cos(πl/5))/2.
        assert_relative_eq!(
            Window::Hanning.factor(1, order(5)),
            0.904_508,
            epsilon = 1e-6
        );
        assert_relative_eq!(
            Window::Lanczos.factor(4, order(5)),
            0.233_872,
            epsilon = 1e-6
        );
        assert!((0..5).all(|l| Window::None.factor(l, order(5)) == 1.0));
    }

    #[test]
    fn names_round_trip() {
        for window in Window::ALL {
            assert_eq!(Window::from_name(window.name()), Some(window));
        }
        assert_eq!(Window::from_name("hann"), None);
    }

    /// A window keeps band 0: a uniform sky (the furnace) is unchanged
    /// (measured: within 4.8e-7 of 2).
    #[test]
    fn the_furnace_stays_a_furnace() {
        let light = project_environment(&Environment::uniform(Vec3::splat(2.0)), order(5));
        for window in Window::ALL {
            let windowed = window.apply(&light);
            assert_eq!(windowed.coeffs()[0], light.coeffs()[0]);
            for dir in [Vec3::Y, Vec3::NEG_Z, Vec3::new(0.6, 0.0, 0.8)] {
                assert_relative_eq!(windowed.eval(dir), Vec3::splat(2.0), epsilon = 1e-4);
            }
        }
    }

    /// A 2° sun at order 9: the truncated expansion dips below zero away
    /// from the sun, to 13.7% of its peak (measured); Hanning's ripples reach
    /// 2.8% and Lanczos's 4.3%.
    #[test]
    fn windows_shrink_the_ringing_of_a_sun() {
        let (w, h) = (256, 128);
        let sun = Vec3::new(0.3, 0.8, 0.2).normalize();
        let mut texels = vec![Vec3::ZERO; w * h];
        for (i, t) in texels.iter_mut().enumerate() {
            let theta = std::f32::consts::PI * ((i / w) as f32 + 0.5) / h as f32;
            let phi = 2.0 * std::f32::consts::PI * ((i % w) as f32 + 0.5) / w as f32;
            let d = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            if d.dot(sun) > 2f32.to_radians().cos() {
                *t = Vec3::splat(1000.0);
            }
        }
        let env = Environment::new("sun", w, h, texels).unwrap();
        let light = project_environment(&env, order(9));
        let most_negative = |sh: &ShRgb| {
            let mut least = f32::INFINITY;
            for i in 0..2000 {
                // A spiral of directions over the sphere.
                let y = 1.0 - 2.0 * (i as f32 + 0.5) / 2000.0;
                let r = (1.0 - y * y).sqrt();
                let phi = i as f32 * 2.399_963;
                least = least.min(sh.eval(Vec3::new(r * phi.cos(), y, r * phi.sin())).x);
            }
            least / sh.eval(sun).x
        };
        let plain = most_negative(&light);
        let hanning = most_negative(&Window::Hanning.apply(&light));
        let lanczos = most_negative(&Window::Lanczos.apply(&light));
        println!("least over peak: none {plain}, Hanning {hanning}, Lanczos {lanczos}");
        assert!(plain < -0.1, "{plain}");
        assert!(hanning > plain / 4.0, "{hanning} against {plain}");
        assert!(lanczos > plain / 3.0, "{lanczos} against {plain}");
    }
}
