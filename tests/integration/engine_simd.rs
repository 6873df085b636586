//! The kernels' copies for each instruction set (`engine::simd`) must give
//! the same measurement bit for bit: a part measured on a lab PC with AVX-512
//! and on a line PC without it is the same part.
//!
//! The only test in this binary that changes the process-wide limit; the
//! others, running meanwhile, take whichever copy it leaves, which is why
//! every copy must agree.

use sheen::engine::control::RunControl;
use sheen::engine::pipeline::{Method, Params, Reconstruction, run};
use sheen::engine::simd::{self, Level};
use sheen::engine::unwrap::OrderCheck;
use sheen::sim::{SceneKind, SimConfig, simulate};

fn f32_bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Named maps, each element as its bits.
type Maps = Vec<(String, Vec<u64>)>;

/// Every map the per-pixel kernels write, and the cloud, by name.
fn maps(rec: &Reconstruction) -> Maps {
    let mut out = Vec::new();
    let mut push = |name: String, v: Vec<u64>| out.push((name, v));
    let widen = |v: Vec<u32>| v.into_iter().map(u64::from).collect::<Vec<u64>>();
    for cam in &rec.cameras {
        for (s, set) in cam.sets.iter().enumerate() {
            let c = &cam.camera;
            push(format!("{c} set {s} wrapped phase"), widen(f32_bits(&set.wrapped_phase_rad)));
            push(format!("{c} set {s} modulation"), widen(f32_bits(&set.modulation_dn)));
            push(format!("{c} set {s} phase sigma"), widen(f32_bits(&set.phase_sigma_rad)));
            push(format!("{c} set {s} saturation count"), set.saturation_count.iter().map(|&n| u64::from(n)).collect());
        }
        for (m, u) in cam.unwrapped.unwrapped_phase_rad.iter().enumerate() {
            push(format!("{} unwrapped {m}", cam.camera), widen(f32_bits(u)));
        }
        push(format!("{} order flags", cam.camera), cam.unwrapped.order_flags.iter().map(|&f| u64::from(f)).collect());
        push(
            format!("{} order evidence", cam.camera),
            cam.unwrapped.order_evidence.iter().map(|&e| u64::from(e)).collect(),
        );
        push(format!("{} fused phase", cam.camera), widen(f32_bits(&cam.fused.fused_phase_rad)));
        push(format!("{} fused sigma", cam.camera), widen(f32_bits(&cam.fused.fused_sigma_rad)));
        push(format!("{} source", cam.camera), cam.fused.source_set.iter().map(|&s| s as u8 as u64).collect());
    }
    let cloud = &rec.stereo.as_ref().expect("a stereo result").cloud;
    push("cloud xyz".into(), cloud.xyz.iter().flat_map(|p| p.map(f64::to_bits)).collect());
    push("cloud sigma_z".into(), widen(f32_bits(&cloud.sigma_z)));
    out
}

#[test]
fn every_instruction_set_gives_the_same_measurement_bit_for_bit() {
    // A width and height that no vector or tile length divides; 8-bit data
    // so that a good share of the pixels has saturated samples.
    let mut config = SimConfig::new(SceneKind::WatchPlate, 203, 77);
    config.bits = 8;
    config.noise_sigma_dn = 1.5;
    let sim = simulate(&config, &RunControl::new()).expect("simulate");
    let variants = [
        (Method::Hdr, OrderCheck::Evidence),
        (Method::Hdr, OrderCheck::Strict),
        (Method::Hdr, OrderCheck::Off),
        (Method::Masked, OrderCheck::Evidence),
        (Method::Standard, OrderCheck::Evidence),
    ];
    let levels: Vec<Level> = Level::ALL.into_iter().filter(|&l| l <= simd::supported()).collect();
    let mut compared = 0;
    for (method, order_check) in variants {
        let params = Params { method, order_check, ..Params::default() };
        let mut reference: Option<(Level, Maps)> = None;
        for &level in &levels {
            simd::set_limit(level);
            assert_eq!(simd::level(), level);
            let rec = run(&sim.measurement, &params, None, &RunControl::new()).expect("reconstruct");
            let got = maps(&rec);
            match &reference {
                None => reference = Some((level, got)),
                Some((first, want)) => {
                    for ((name, a), (_, b)) in want.iter().zip(&got) {
                        let differ = a.iter().zip(b).filter(|(x, y)| x != y).count();
                        assert!(
                            a.len() == b.len() && differ == 0,
                            "{method:?}/{order_check:?}: {name} differs between {first:?} and {level:?} at {differ} of {} elements",
                            a.len()
                        );
                    }
                    compared += 1;
                }
            }
        }
    }
    simd::set_limit(Level::Avx512);
    // The saturated share that makes the comparison worth having.
    let rec = run(&sim.measurement, &Params::default(), None, &RunControl::new()).expect("reconstruct");
    let stats = &rec.cameras[0].sets[3].stats;
    assert!(
        stats.partially_saturated * 10 > stats.pixels,
        "{} of {} pixels saturated",
        stats.partially_saturated,
        stats.pixels
    );
    // On x86-64 every CI machine has at least AVX2, so at least two copies met.
    if cfg!(target_arch = "x86_64") {
        assert!(compared >= variants.len(), "only {levels:?} could be compared");
    }
}
