use super::*;
use crate::Environment;
use crate::environment::direction_from_angles;
use crate::sh::basis::eval_sum;
use crate::sh::test_util::{environment_of, noise};
use crate::sh::{project_environment, sh_index};
use glam::Vec3;
use proptest::prelude::*;
use std::f32::consts::{FRAC_PI_2, PI, TAU};

fn random_coeffs(order: ShOrder, seed: u64) -> Vec<f32> {
    let mut rand = noise(seed);
    (0..order.coeff_count()).map(|_| rand()).collect()
}

fn rotate(order: ShOrder, q: Quat, coeffs: &[f32]) -> Vec<f32> {
    let mut out = vec![0.0; coeffs.len()];
    ShRotation::from_quat(order, q)
        .unwrap()
        .apply(coeffs, &mut out);
    out
}

fn band_norms(order: ShOrder, c: &[f32]) -> Vec<f32> {
    (0..order.bands())
        .map(|l| {
            c[l * l..(l + 1) * (l + 1)]
                .iter()
                .map(|x| x * x)
                .sum::<f32>()
                .sqrt()
        })
        .collect()
}

fn arbitrary_rotation() -> impl Strategy<Value = Quat> {
    (0.0f32..PI, 0.0f32..TAU, -PI..PI)
        .prop_map(|(t, p, angle)| Quat::from_axis_angle(direction_from_angles(t, p), angle))
}

/// An analytic, smooth, non-band-limited, non-symmetric radiance.
fn sky(d: Vec3) -> Vec3 {
    let sun = Vec3::new(0.3, 0.8, -0.5).normalize();
    Vec3::new(
        (1.5 * d.dot(sun)).exp(),
        1.0 + 0.5 * d.x * d.y + 0.3 * d.z,
        (d.dot(Vec3::new(0.6, -0.2, 0.4)) + 1.0).powi(2),
    )
}

/// Projects `sky` and `sky ∘ R⁻¹`, each sampled directly, and checks that
/// rotating the first projection gives the second. The two maps sample
/// different functions, so they agree to the projection error of a
/// 256×128 map (measured ≤ 2e-5 of c_00).
fn check_against_reprojection(q: Quat) {
    let order = ShOrder::new(8).unwrap();
    let (w, h) = (256, 128);
    let inverse = q.inverse();
    let f: Environment = environment_of("sky", w, h, sky);
    let g: Environment = environment_of("rotated sky", w, h, |d| sky(inverse * d));
    let rotated = project_environment(&f, order).rotated(&ShRotation::from_quat(order, q).unwrap());
    let reprojected = project_environment(&g, order);
    let scale = reprojected.coeffs()[0].max_element();
    for (i, (a, b)) in rotated
        .coeffs()
        .iter()
        .zip(reprojected.coeffs())
        .enumerate()
    {
        assert!(
            (*a - *b).abs().max_element() < 1e-4 * scale,
            "rotation {q}: coefficient {i}: rotated {a}, re-projected {b}"
        );
    }
}

#[test]
fn rotation_about_each_axis_matches_reprojection() {
    for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
        for angle in [0.4, FRAC_PI_2, 2.5] {
            check_against_reprojection(Quat::from_axis_angle(axis, angle));
        }
    }
}

#[test]
fn band_1_turns_the_x_lobe_to_minus_z_under_a_quarter_turn_about_y() {
    // R_y(90°) maps +X to −Z, so the function x becomes −z.
    let order = ShOrder::new(2).unwrap();
    let mut f = [0.0; 4];
    f[sh_index(1, 1)] = 1.0;
    let g = rotate(order, Quat::from_rotation_y(FRAC_PI_2), &f);
    let mut want = [0.0; 4];
    want[sh_index(1, -1)] = -1.0;
    for (a, b) in g.iter().zip(&want) {
        assert!((a - b).abs() < 1e-6, "{g:?}");
    }
}

#[test]
fn identity_is_identity_and_composition_composes() {
    let order = ShOrder::new(12).unwrap();
    let c = random_coeffs(order, 11);
    let mut out = vec![0.0; c.len()];
    ShRotation::identity(order).apply(&c, &mut out);
    assert_eq!(out, c);
    let r1 = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 2.0);
    let r2 = Quat::from_euler(glam::EulerRot::ZXY, 1.7, 0.2, -0.6);
    let sequential = rotate(order, r1, &rotate(order, r2, &c));
    let composed = rotate(order, r1 * r2, &c);
    for (a, b) in sequential.iter().zip(&composed) {
        assert!((a - b).abs() < 1e-4, "{a} vs {b}");
    }
}

#[test]
fn non_rotations_are_rejected() {
    let order = ShOrder::new(3).unwrap();
    assert!(ShRotation::from_mat3(order, Mat3::from_diagonal(Vec3::new(1.0, 1.0, -1.0))).is_none());
    assert!(ShRotation::from_mat3(order, Mat3::from_diagonal(Vec3::splat(2.0))).is_none());
    assert!(ShRotation::from_mat3(order, Mat3::from_cols_array(&[f32::NAN; 9])).is_none());
    assert!(ShRotation::from_quat(order, Quat::from_xyzw(0.0, 0.0, 0.0, 0.0)).is_none());
    assert!(ShRotation::from_mat3(order, Mat3::from_rotation_x(0.7)).is_some());
}

#[test]
#[should_panic(expected = "cannot rotate 25 coefficients")]
fn rotating_above_the_rotations_order_panics() {
    let rotation = ShRotation::identity(ShOrder::new(3).unwrap());
    let mut out = [0.0; 25];
    rotation.apply(&[0.0; 25], &mut out);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The defining identity, pointwise: Σ c'_i Y_i(ω) = Σ c_i Y_i(R⁻¹ω),
    /// exact for every order because bands are invariant under rotation.
    #[test]
    fn rotated_coefficients_evaluate_the_rotated_function(
        q in arbitrary_rotation(),
        order in 1u32..=16,
        seed in any::<u64>(),
        t in 0.0f32..PI,
        p in 0.0f32..TAU,
    ) {
        let order = ShOrder::new(order).unwrap();
        let c = random_coeffs(order, seed);
        let rotated = rotate(order, q, &c);
        let d = direction_from_angles(t, p);
        let want = eval_sum(order, &c, q.inverse() * d);
        let got = eval_sum(order, &rotated, d);
        prop_assert!((got - want).abs() < 2e-4 * order.get() as f32, "{} vs {}", got, want);
    }

    #[test]
    fn rotation_preserves_the_norm_of_each_band(q in arbitrary_rotation(), seed in any::<u64>()) {
        let order = ShOrder::MAX;
        let c = random_coeffs(order, seed);
        let before = band_norms(order, &c);
        let after = band_norms(order, &rotate(order, q, &c));
        for (l, (a, b)) in before.iter().zip(&after).enumerate() {
            prop_assert!((a - b).abs() < 1e-4 * a.max(1.0), "band {}: {} vs {}", l, a, b);
        }
    }

    #[test]
    fn rotation_from_mat3_equals_rotation_from_quat(q in arbitrary_rotation()) {
        let order = ShOrder::new(9).unwrap();
        let a = ShRotation::from_quat(order, q).unwrap();
        let b = ShRotation::from_mat3(order, Mat3::from_quat(q)).unwrap();
        for (x, y) in a.blocks.iter().zip(&b.blocks) {
            prop_assert!((x - y).abs() < 1e-5);
        }
    }
}

/// The Euler path against the matrix built by the recurrence, on every
/// kind of rotation, the poles included (β = 0 or π, where the
/// decomposition's α is arbitrary).
fn check_euler(order: ShOrder, r: Mat3, seed: u64) {
    let c = random_coeffs(order, seed);
    let mut want = vec![0.0; c.len()];
    ShRotation::from_mat3(order, r)
        .unwrap()
        .apply(&c, &mut want);
    let mut got = c.clone();
    EulerShRotation::new(order).apply(r, &mut got);
    for (i, (a, b)) in got.iter().zip(&want).enumerate() {
        assert!(
            (a - b).abs() < 2e-5 * order.get() as f32,
            "{r}: coefficient {i}: {a} vs {b}"
        );
    }
}

#[test]
fn euler_rotation_at_the_poles_and_about_each_axis() {
    let order = ShOrder::new(6).unwrap();
    for r in [
        Mat3::IDENTITY,
        Mat3::from_rotation_y(0.7),
        Mat3::from_rotation_x(PI),
        Mat3::from_rotation_x(PI) * Mat3::from_rotation_y(-2.0),
        Mat3::from_rotation_x(1e-4) * Mat3::from_rotation_y(1.3),
        Mat3::from_rotation_z(0.9),
        Mat3::from_rotation_x(-FRAC_PI_2),
        Mat3::from_rotation_z(PI - 1e-5),
    ] {
        check_euler(order, r, 3);
    }
}

/// In chunks, with more chunks than the order needs and garbage in the
/// padding: the coefficients are those of [`EulerShRotation::apply`]
/// and the padding comes out zero.
#[test]
fn euler_rotation_in_chunks_zeroes_the_padding() {
    let order = ShOrder::new(5).unwrap();
    let rotation = EulerShRotation::new(order);
    let r = Mat3::from_quat(Quat::from_euler(glam::EulerRot::XYZ, 0.4, -1.2, 2.3));
    let c = random_coeffs(order, 5);
    let mut want = c.clone();
    rotation.apply(r, &mut want);
    let mut chunks = [[7.0f32; CHUNK]; 4];
    chunks.as_flattened_mut()[..25].copy_from_slice(&c);
    rotation.apply_chunks(r, &mut chunks);
    let flat = chunks.as_flattened();
    assert_eq!(&flat[..25], &want[..]);
    assert!(flat[25..].iter().all(|&x| x == 0.0), "{:?}", &flat[25..]);
}

#[test]
#[should_panic(expected = "1 chunks cannot hold")]
fn euler_rotation_into_too_few_chunks_panics() {
    EulerShRotation::new(ShOrder::new(5).unwrap())
        .apply_chunks(Mat3::IDENTITY, &mut [[0.0; CHUNK]; 1]);
}

#[test]
#[should_panic(expected = "cannot rotate 25 coefficients")]
fn euler_rotation_above_its_order_panics() {
    EulerShRotation::new(ShOrder::new(3).unwrap()).apply(Mat3::IDENTITY, &mut [0.0; 25]);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn euler_rotation_equals_the_recurrence(
        q in arbitrary_rotation(),
        order in 1u32..=16,
        seed in any::<u64>(),
    ) {
        check_euler(ShOrder::new(order).unwrap(), Mat3::from_quat(q), seed);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(6))]

    #[test]
    fn random_rotations_match_reprojection(q in arbitrary_rotation()) {
        check_against_reprojection(q);
    }
}
