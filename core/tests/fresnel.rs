//! Claim: glass (`dielectric`) reflects and refracts as the Fresnel equations and Snell's law say, splits the
//! flux without absorbing any (R + T = 1 in `Importance` mode), scales transmitted radiance by 1/η'² in
//! `Radiance` mode, and reflects everything beyond the critical angle.
//!
//! R and T are read off `Bsdf::sample` as an integrator sees them: with `u = 0` the sample is the reflection
//! (chosen with probability F), with `u → 1` the refraction; `f·|cos θi|` is then R or T. They are compared with
//! Hecht's form of the Fresnel equations, rs = −sin(θi − θt)/sin(θi + θt), rp = tan(θi − θt)/tan(θi + θt),
//! computed in f64 independently of `math::fresnel_dielectric`. Tolerances are f32 rounding.

mod common;

use common::{dir, flat, sampler};
use glam::Vec3A;
use photon_core::Rgb;
use photon_core::material::bsdf::{Bsdf, BsdfSample, Bxdf, TransportMode};
use photon_core::math::fmath;

const U_LAST: f32 = 1.0 - f32::EPSILON / 2.0;

fn glass(eta: f32) -> Bsdf {
    flat(Bxdf::Dielectric { eta, tint: Rgb::ONE })
}

/// Reflected and transmitted fractions for `wo`, and the two samples.
fn r_and_t(b: &Bsdf, wo: Vec3A, mode: TransportMode) -> (f32, f32, Option<BsdfSample>, Option<BsdfSample>) {
    let r = b.sample(wo, 0.0, glam::Vec2::ZERO, mode);
    let t = b.sample(wo, U_LAST, glam::Vec2::ZERO, mode);
    let part = |s: &Option<BsdfSample>| s.map_or(0.0, |s| s.f.x * s.wi.z.abs());
    let (rv, tv) = (part(&r), part(&t));
    (rv, if t.is_some_and(|t| t.delta && t.wi.z * wo.z < 0.0) { tv } else { 0.0 }, r, t)
}

/// Unpolarised Fresnel reflectance for incidence angle `ti` from a medium of index `n1` into `n2` (Hecht).
fn hecht(ti: f64, n1: f64, n2: f64) -> f64 {
    let st = n1 / n2 * ti.sin();
    if st >= 1.0 {
        return 1.0;
    }
    if ti == 0.0 {
        return ((n1 - n2) / (n1 + n2)).powi(2);
    }
    let tt = st.asin();
    let rs = -(ti - tt).sin() / (ti + tt).sin();
    let rp = (ti - tt).tan() / (ti + tt).tan();
    0.5 * (rs * rs + rp * rp)
}

#[test]
fn normal_incidence_reflects_four_percent_for_eta_one_and_a_half() {
    let b = glass(1.5);
    for wo in [Vec3A::Z, -Vec3A::Z] {
        let (r, t, rs, _) = r_and_t(&b, wo, TransportMode::Importance);
        assert!((r - 0.04).abs() < 1e-6, "wo = {wo}: R = {r}");
        assert!((t - 0.96).abs() < 1e-6, "wo = {wo}: T = {t}");
        let rs = rs.unwrap();
        assert!((rs.pdf - 0.04).abs() < 1e-6 && rs.delta && (rs.wi - wo).length() < 1e-6);
    }
    for eta in [1.33f32, 2.4] {
        let (r, _, _, _) = r_and_t(&glass(eta), Vec3A::Z, TransportMode::Importance);
        let want = ((eta - 1.0) / (eta + 1.0)).powi(2);
        assert!((r - want).abs() < 1e-6, "η = {eta}: R = {r}, want {want}");
    }
}

#[test]
fn reflectance_follows_the_fresnel_equations_and_refraction_follows_snell() {
    for eta in [1.33f32, 1.5, 2.4] {
        for side in [1.0f32, -1.0] {
            // Outside (side +1) light goes from index 1 into eta; inside, from eta into 1.
            let (n1, n2) = if side > 0.0 { (1.0, f64::from(eta)) } else { (f64::from(eta), 1.0) };
            for k in 0..=89 {
                let theta = (k as f32).to_radians();
                let phi = 0.1 * k as f32;
                let wo = side * dir(theta, phi);
                let b = glass(eta);
                let (r, t, _, ts) = r_and_t(&b, wo, TransportMode::Importance);
                let want = hecht(f64::from(theta), n1, n2);
                let at = format!("η = {eta}, side {side}, θ = {k}°");
                assert!((f64::from(r) - want).abs() < 2e-5, "{at}: R = {r}, Fresnel {want}");
                if want < 1.0 {
                    let ts = ts.unwrap();
                    let sin_o = f64::from(fmath::sin(theta));
                    let sin_t = f64::from((ts.wi.x * ts.wi.x + ts.wi.y * ts.wi.y).sqrt());
                    assert!((n1 * sin_o - n2 * sin_t).abs() < 1e-5, "{at}: Snell {n1}·{sin_o} ≠ {n2}·{sin_t}");
                    // In the plane of incidence, on the far side of the normal.
                    let (o, i) = (wo.truncate(), ts.wi.truncate());
                    assert!(
                        (o.x * i.y - o.y * i.x).abs() < 1e-5 && (theta == 0.0 || o.x * i.x + o.y * i.y <= 0.0),
                        "{at}"
                    );
                    assert!(ts.wi.z * wo.z < 0.0, "{at}: transmission stays on the same side");
                } else {
                    assert_eq!(t, 0.0, "{at}");
                }
            }
        }
    }
}

#[test]
fn reflected_plus_transmitted_flux_is_the_incident_flux() {
    for eta in [1.33f32, 1.5, 2.4] {
        for side in [1.0f32, -1.0] {
            for k in 0..=89 {
                let theta = (k as f32).to_radians();
                let wo = side * dir(theta, 0.0);
                let b = glass(eta);
                let (r, t, _, _) = r_and_t(&b, wo, TransportMode::Importance);
                assert!((r + t - 1.0).abs() < 2e-6, "η = {eta}, side {side}, θ = {k}°: R + T = {}", r + t);
                // Radiance is compressed on entering the denser medium: T / η'² with η' seen from wo.
                let (_, t_radiance, _, _) = r_and_t(&b, wo, TransportMode::Radiance);
                let etap = if side > 0.0 { eta } else { 1.0 / eta };
                assert!((t_radiance - t / (etap * etap)).abs() < 2e-6 * t.max(1.0), "η = {eta}, side {side}, θ = {k}°");
            }
        }
    }
}

#[test]
fn stokes_relation_reflectance_is_the_same_from_both_sides() {
    for eta in [1.33f32, 1.5, 2.4] {
        let b = glass(eta);
        // Up to 85°: towards grazing incidence the refracted ray nears the critical angle inside, where F has an
        // infinite slope and the f32 rounding of the refracted direction, not the physics, sets the difference.
        for k in 0..=85 {
            let wo = dir((k as f32).to_radians(), 0.7);
            let (r_out, _, _, ts) = r_and_t(&b, wo, TransportMode::Importance);
            let wt = ts.unwrap().wi;
            // Looking back along the refracted ray from inside.
            let (r_in, _, _, back) = r_and_t(&b, wt, TransportMode::Importance);
            assert!((r_out - r_in).abs() < 2e-5, "η = {eta}, θ = {k}°: {r_out} vs {r_in}");
            assert!((back.unwrap().wi - wo).length() < 1e-4, "η = {eta}, θ = {k}°: the path does not retrace");
        }
    }
}

#[test]
fn beyond_the_critical_angle_glass_reflects_everything() {
    for eta in [1.33f32, 1.5, 2.4] {
        let b = glass(eta);
        let critical = fmath::asin(1.0 / eta);
        let mut rng = sampler(5, u64::from(eta.to_bits()));
        for k in 1..=50 {
            let theta = critical + (std::f32::consts::FRAC_PI_2 - critical) * k as f32 / 51.0;
            let wo = -dir(theta, 0.3 * k as f32);
            for _ in 0..200 {
                for mode in [TransportMode::Radiance, TransportMode::Importance] {
                    let s = b.sample(wo, rng.next_f32(), rng.next_2d(), mode).unwrap();
                    let weight = s.f * s.wi.z.abs() / s.pdf;
                    assert!(s.delta && s.pdf == 1.0, "η = {eta}, θ = {theta}: {s:?}");
                    assert!((weight - Rgb::ONE).abs().max_element() < 1e-5, "η = {eta}, θ = {theta}: weight {weight}");
                    assert!((s.wi - Vec3A::new(-wo.x, -wo.y, wo.z)).length() < 1e-5, "not the mirror direction");
                }
            }
        }
        // Just inside the critical angle some light still gets out.
        let wo = -dir(critical - 0.01, 0.0);
        let (_, t, _, _) = r_and_t(&b, wo, TransportMode::Importance);
        assert!(t > 0.0, "η = {eta}: no transmission below the critical angle");
    }
}
