//! The environment split into area lights (§4.2.1), after Kollig and Keller
//! 2003: light directions placed where the luminance is, then relaxed by
//! Lloyd's algorithm with the luminance as density, so that each light's
//! region W_i (its spherical Voronoi cell) holds a share of the light and
//! bright, small features get small regions. Each light carries its
//! radiosity B_i = ∫_{W_i} L dω (eq. 4's normalization: a direction's
//! radiance times its solid angle), its solid angle Ω_i, the direction
//! ω_i at its luminance-weighted centroid, and the extent its light comes
//! from, which sets its penumbrae.

use glam::Vec3;
use rayon::prelude::*;
use shadow_core::{Environment, Error, Result, environment::luminance};

/// One area light W_i.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AreaLight {
    /// ω_i: the unit direction toward the light, its region's centroid.
    pub direction: Vec3,
    /// B_i = ∫_{W_i} L dω, linear RGB.
    pub radiosity: Vec3,
    /// Ω_i, steradians.
    pub solid_angle: f32,
    /// The solid angle its light comes from, which sets the width of its
    /// penumbrae (§4.2.2: the maps are blurred by the light's size): that
    /// of the cap with the same power-weighted mean 1 − cos θ about ω_i,
    /// 4π·E[1 − ω·ω_i] (exact for a uniform cap), at most Ω_i. A region
    /// holding a sun and the sky around it blurs by the sun's size (its
    /// cells around an 8° sun were up to 9 times its size); a region of even
    /// radiance by its own.
    pub extent: f32,
}

/// Relaxation runs on a copy of the map at most this many texels wide
/// (integral-preserving); the final regions take every texel of the map.
const WORK_WIDTH: usize = 256;

/// Maps narrower than this are split into finer texels (each an exact
/// part of one of the map's) so that regions are not made of a few texels.
const MIN_WIDTH: usize = 128;

/// Lloyd iterations: the centroids move by well under a texel of the
/// working map after this many on the shipped environments.
const ITERATIONS: usize = 24;

/// Splits `environment` into `count` area lights.
///
/// Fails with [`Error::InvalidConfig`] for a count of zero or more lights
/// than the copy the lights are placed on has texels, each seed taking one
/// of its own: a map wider than 256 texels is relaxed on a copy 256 × 128
/// texels, one narrower than 128 on its texels split into finer ones (so
/// that a 16 × 8 map serves more than its 128 texels' worth of lights).
pub fn decompose(environment: &Environment, count: usize) -> Result<Vec<AreaLight>> {
    if count == 0 {
        return Err(Error::config(
            "deferred-shadow",
            "0 area lights: at least one is needed",
        ));
    }
    let work = if environment.width() > WORK_WIDTH {
        environment.downsampled(WORK_WIDTH, WORK_WIDTH / 2)
    } else {
        environment.clone()
    };
    let samples = Samples::of(&work);
    if count > samples.directions.len() {
        return Err(Error::config(
            "deferred-shadow",
            format!(
                "{count} area lights for a {}×{} environment: at most {}, the texels of the {}×{} copy the lights are placed on",
                environment.width(),
                environment.height(),
                samples.directions.len(),
                work.width(),
                work.height()
            ),
        ));
    }
    let mut centres = samples.importance_seeds(count);
    for _ in 0..ITERATIONS {
        let owner = samples.nearest(&centres);
        centres = samples.weighted_centroids(&owner, &centres);
    }
    let full = Samples::of(environment);
    let regions = full.nearest(&centres);
    let mut lights: Vec<AreaLight> = centres
        .iter()
        .map(|&direction| AreaLight {
            direction,
            radiosity: Vec3::ZERO,
            solid_angle: 0.0,
            extent: 0.0,
        })
        .collect();
    let mut centroid = vec![Vec3::ZERO; count];
    for (t, &r) in regions.iter().enumerate() {
        let light = &mut lights[r as usize];
        light.radiosity += full.radiance[t] * full.solid_angle[t];
        light.solid_angle += full.solid_angle[t];
        centroid[r as usize] += full.directions[t] * full.weight[t];
    }
    for (light, c) in lights.iter_mut().zip(centroid) {
        light.direction = c.try_normalize().unwrap_or(light.direction);
    }
    // The power-weighted mean of 1 − cos θ about each direction.
    let mut spread = vec![(0.0f64, 0.0f64); count];
    for (t, &r) in regions.iter().enumerate() {
        let power = (luminance(full.radiance[t]).max(0.0) * full.solid_angle[t]) as f64;
        // A texel's own spread, as a cap of its solid angle, plus its
        // offset (the parallel-axis rule, to first order).
        let own = full.solid_angle[t] / (4.0 * std::f32::consts::PI);
        let off = (1.0 - full.directions[t].dot(lights[r as usize].direction)).max(0.0);
        spread[r as usize].0 += power * (off + own) as f64;
        spread[r as usize].1 += power;
    }
    for (light, (moment, power)) in lights.iter_mut().zip(spread) {
        let cap = 4.0 * std::f64::consts::PI * moment / power;
        light.extent = if power > 0.0 && cap.is_finite() {
            (cap as f32).min(light.solid_angle)
        } else {
            light.solid_angle
        };
    }
    Ok(lights)
}

/// A map's texels as points on the sphere with their weights.
pub(crate) struct Samples {
    pub(crate) directions: Vec<Vec3>,
    pub(crate) solid_angle: Vec<f32>,
    pub(crate) radiance: Vec<Vec3>,
    /// Luminance × solid angle, plus a little of the mean so that a black
    /// region still pulls its centre toward its middle.
    weight: Vec<f32>,
}

impl Samples {
    /// The texels of `env`, each split into f × f finer ones (f the least
    /// whole factor that makes the map at least [`MIN_WIDTH`] wide): the
    /// same piecewise-constant radiance, so every integral is the map's.
    pub(crate) fn of(env: &Environment) -> Samples {
        let f = MIN_WIDTH.div_ceil(env.width()).max(1);
        let (w, h) = (env.width() * f, env.height() * f);
        let mut s = Samples {
            directions: Vec::with_capacity(w * h),
            solid_angle: Vec::with_capacity(w * h),
            radiance: Vec::with_capacity(w * h),
            weight: Vec::with_capacity(w * h),
        };
        let pi = std::f64::consts::PI;
        for row in 0..h {
            let (t0, t1) = (pi * row as f64 / h as f64, pi * (row + 1) as f64 / h as f64);
            let omega = ((t0.cos() - t1.cos()) * 2.0 * pi / w as f64) as f32;
            let theta = (0.5 * (t0 + t1)) as f32;
            for col in 0..w {
                let phi = (2.0 * pi * (col as f64 + 0.5) / w as f64) as f32;
                let l = env.texel(row / f, col / f);
                s.directions
                    .push(shadow_core::environment::direction_from_angles(theta, phi));
                s.solid_angle.push(omega);
                s.radiance.push(l);
                s.weight.push(luminance(l).max(0.0) * omega);
            }
        }
        let mean = s.weight.iter().sum::<f32>() / (4.0 * std::f32::consts::PI);
        for (weight, omega) in s.weight.iter_mut().zip(&s.solid_angle) {
            *weight += 1e-3 * mean.max(f32::MIN_POSITIVE) * omega;
        }
        s
    }

    /// `count` directions drawn in proportion to the weights, stratified:
    /// the texel at each (k + ½)/count of the cumulative weight (a texel
    /// drawn twice is moved to the next unused one). `count` must not
    /// exceed the samples, or no unused one is left.
    fn importance_seeds(&self, count: usize) -> Vec<Vec3> {
        let total: f64 = self.weight.iter().map(|&w| w as f64).sum();
        let mut used = vec![false; self.weight.len()];
        let mut seeds = Vec::with_capacity(count);
        let mut cumulative = 0.0f64;
        let mut t = 0;
        for k in 0..count {
            let target = (k as f64 + 0.5) / count as f64 * total;
            while t + 1 < self.weight.len() && cumulative + (self.weight[t] as f64) < target {
                cumulative += self.weight[t] as f64;
                t += 1;
            }
            let mut pick = t;
            while used[pick] {
                pick = (pick + 1) % used.len();
            }
            used[pick] = true;
            seeds.push(self.directions[pick]);
        }
        seeds
    }

    /// The index of the nearest centre of every texel.
    fn nearest(&self, centres: &[Vec3]) -> Vec<u32> {
        self.directions
            .par_iter()
            .map(|d| {
                let mut best = (f32::NEG_INFINITY, 0u32);
                for (i, c) in centres.iter().enumerate() {
                    let dot = d.dot(*c);
                    if dot > best.0 {
                        best = (dot, i as u32);
                    }
                }
                best.1
            })
            .collect()
    }

    /// Each region's weighted centroid, on the sphere; a region that lost
    /// every texel keeps its centre.
    fn weighted_centroids(&self, owner: &[u32], centres: &[Vec3]) -> Vec<Vec3> {
        let mut sums = vec![Vec3::ZERO; centres.len()];
        for (t, &o) in owner.iter().enumerate() {
            sums[o as usize] += self.directions[t] * self.weight[t];
        }
        sums.iter()
            .zip(centres)
            .map(|(s, c)| s.try_normalize().unwrap_or(*c))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn sunny() -> Environment {
        let (w, h) = (128, 64);
        let texels = (0..w * h)
            .map(|i| {
                let (row, col) = (i / w, i % w);
                if (10..13).contains(&row) && (40..43).contains(&col) {
                    Vec3::splat(500.0)
                } else {
                    Vec3::new(0.2, 0.3, 0.5) * (1.2 - row as f32 / h as f32)
                }
            })
            .collect();
        Environment::new("sunny", w, h, texels).unwrap()
    }

    #[test]
    fn regions_tile_the_sphere_and_hold_all_the_light() {
        for env in [Environment::uniform(Vec3::ONE), sunny()] {
            for q in [16, 32, 64] {
                let lights = decompose(&env, q).unwrap();
                assert_eq!(lights.len(), q);
                let omega: f32 = lights.iter().map(|l| l.solid_angle).sum();
                assert_relative_eq!(omega, 4.0 * std::f32::consts::PI, max_relative = 1e-4);
                let power: Vec3 = lights.iter().map(|l| l.radiosity).sum();
                assert_relative_eq!(power, env.integral(), max_relative = 1e-4);
                assert!(lights.iter().all(|l| l.solid_angle > 0.0));
                for l in &lights {
                    assert_relative_eq!(l.direction.length(), 1.0, epsilon = 1e-5);
                }
            }
        }
    }

    /// A sun 8.4° across (0.0169 sr, radiance 500) in a sky of 0.1, in 32
    /// lights: the cells around the sun also hold sky, up to 9 times the
    /// sun's solid angle (measured 0.157 sr), and blurred their shadows by
    /// all of it; their extents are the sun's (measured at most 0.0116 sr).
    #[test]
    fn the_cells_of_a_sun_blur_by_the_suns_size() {
        let (w, h) = (128, 64);
        let sun = Vec3::new(1.0, 1.0, 0.0).normalize();
        let radius = 4.2f32.to_radians();
        let texels = (0..w * h)
            .map(|i| {
                let theta = std::f32::consts::PI * ((i / w) as f32 + 0.5) / h as f32;
                let phi = std::f32::consts::TAU * ((i % w) as f32 + 0.5) / w as f32;
                let d = shadow_core::environment::direction_from_angles(theta, phi);
                Vec3::splat(if d.dot(sun) > radius.cos() {
                    500.0
                } else {
                    0.1
                })
            })
            .collect();
        let env = Environment::new("sun", w, h, texels).unwrap();
        let disc = std::f32::consts::TAU * (1.0 - radius.cos());
        let lights = decompose(&env, 32).unwrap();
        let at_sun: Vec<&AreaLight> = (lights.iter())
            .filter(|l| l.direction.dot(sun) > radius.cos())
            .collect();
        assert!(!at_sun.is_empty());
        assert!(
            at_sun.iter().any(|l| l.solid_angle > 4.0 * disc),
            "{at_sun:?}"
        );
        for light in at_sun {
            assert!(light.extent <= disc, "{light:?} against {disc} sr");
        }
    }

    #[test]
    fn bright_features_get_small_regions() {
        let env = sunny();
        let lights = decompose(&env, 32).unwrap();
        let sun = env.direction(11, 41);
        let at_sun = lights
            .iter()
            .max_by(|a, b| a.direction.dot(sun).total_cmp(&b.direction.dot(sun)))
            .unwrap();
        let mean = 4.0 * std::f32::consts::PI / 32.0;
        assert!(at_sun.solid_angle < 0.2 * mean, "{} sr", at_sun.solid_angle);
        assert!(at_sun.direction.dot(sun) > 0.99);
        // Its light comes from within the sun's 3 × 3 texels.
        let disc: f32 = (10..13).map(|row| 3.0 * env.solid_angle(row)).sum();
        assert!(at_sun.extent <= at_sun.solid_angle.min(disc), "{at_sun:?}");
        // A uniform sky gets regions of similar size.
        let even = decompose(&Environment::uniform(Vec3::ONE), 32).unwrap();
        let (lo, hi) = even.iter().fold((f32::MAX, 0.0f32), |(lo, hi), l| {
            (lo.min(l.solid_angle), hi.max(l.solid_angle))
        });
        assert!(hi / lo < 1.6, "{lo} .. {hi}");
        // And each light's extent is nearly its cell.
        for light in &even {
            assert!(light.extent > 0.8 * light.solid_angle, "{light:?}");
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]
        /// Any map, any count: the regions tile the sphere and hold all of
        /// the map's light, each a positive solid angle around a unit
        /// direction.
        #[test]
        fn any_map_splits_into_regions_that_tile_it(
            texels in proptest::collection::vec(0.0f32..100.0, 16 * 8),
            q in 1usize..=64,
        ) {
            let texels: Vec<Vec3> = texels.iter().map(|&l| Vec3::new(l, 0.5 * l, 0.25 * l)).collect();
            let env = Environment::new("random", 16, 8, texels).unwrap();
            let lights = decompose(&env, q).unwrap();
            proptest::prop_assert_eq!(lights.len(), q);
            let omega: f32 = lights.iter().map(|l| l.solid_angle).sum();
            proptest::prop_assert!((omega - 4.0 * std::f32::consts::PI).abs() < 1e-3);
            let power: Vec3 = lights.iter().map(|l| l.radiosity).sum();
            let expected = env.integral();
            proptest::prop_assert!((power - expected).abs().max_element() <= 1e-4 * expected.max_element().max(1.0));
            for l in &lights {
                proptest::prop_assert!(l.solid_angle > 0.0);
                proptest::prop_assert!((l.direction.length() - 1.0).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn impossible_counts_are_configuration_errors() {
        let env = Environment::uniform(Vec3::ONE);
        assert!(matches!(
            decompose(&env, 0),
            Err(Error::InvalidConfig { .. })
        ));
        // A map narrower than 128 texels places its lights on finer texels:
        // it serves more lights than it has texels (it refused them), up to
        // the finer texels' count.
        let texels = env.width() * env.height();
        assert!(env.width() < MIN_WIDTH);
        let lights = decompose(&env, 2 * texels).unwrap();
        assert!(lights.iter().all(|l| l.solid_angle > 0.0));
        let omega: f32 = lights.iter().map(|l| l.solid_angle).sum();
        assert_relative_eq!(omega, 4.0 * std::f32::consts::PI, max_relative = 1e-4);
        let finer = Samples::of(&env).directions.len();
        assert!(matches!(
            decompose(&env, finer + 1),
            Err(Error::InvalidConfig { .. })
        ));
    }

    /// A map wider than the working copy has more texels than the copy the
    /// lights are placed on: a count between the two is a configuration
    /// error naming the copy's limit, returned at once (the seeds were once
    /// searched for an unused texel forever).
    #[test]
    fn more_lights_than_the_working_copy_has_texels_are_refused() {
        let (w, h) = (512, 256);
        let env = Environment::new("wide", w, h, vec![Vec3::ONE; w * h]).unwrap();
        let count = WORK_WIDTH * WORK_WIDTH / 2 + 1;
        assert!(count < w * h);
        let (send, receive) = std::sync::mpsc::channel();
        std::thread::spawn(move || send.send(decompose(&env, count)));
        let result = receive
            .recv_timeout(std::time::Duration::from_secs(30))
            .expect("decompose returns within 30 s");
        let Err(Error::InvalidConfig { what, .. }) = result else {
            panic!("{result:?}")
        };
        assert!(what.contains("32768"), "{what}");
    }
}
