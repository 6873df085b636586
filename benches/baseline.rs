//! A straightforward implementation of the per-camera stages, kept as the
//! baseline the engine's speed-up is measured against (issue 8): one pixel at
//! a time, its samples gathered into a fresh vector, Alg. 1 as written, Eq. 5
//! or Eqs. 2-4 with a 3x3 inversion per partially saturated pixel, f64
//! throughout, and Alg. 3 as whole-map loops as the paper writes them.

use sheen::engine::fringe::{CameraFringes, FringeSetInfo};

pub struct BaselineCamera {
    pub fused_phase_rad: Vec<f64>,
    pub source_set: Vec<i8>,
}

pub fn baseline_camera(
    cam: &CameraFringes,
    sets: &[FringeSetInfo],
    threshold: u16,
    min_modulation: f64,
) -> BaselineCamera {
    let len = cam.width * cam.height;
    let m_count = sets.len();
    let mut sat_map = vec![vec![0usize; len]; m_count];
    let mut phi = vec![vec![f64::NAN; len]; m_count];
    for (m, (set, stack)) in sets.iter().zip(&cam.stacks).enumerate() {
        let n = set.shifts();
        for i in 0..len {
            let samples: Vec<f64> = (0..n).map(|k| f64::from(stack.sample(k, i))).collect();
            // Alg. 1
            for &s in &samples {
                if s >= f64::from(threshold) {
                    sat_map[m][i] += 1;
                }
            }
            // Alg. 2
            if sat_map[m][i] == 0 {
                let (mut num, mut den) = (0.0, 0.0);
                for (k, &s) in samples.iter().enumerate() {
                    num += s * set.phase_shifts_rad[k].sin();
                    den += s * set.phase_shifts_rad[k].cos();
                }
                if (num * num + den * den).sqrt() * 2.0 / n as f64 >= min_modulation {
                    phi[m][i] = (-num).atan2(den).rem_euclid(std::f64::consts::TAU);
                }
            } else {
                let mut i_slot = Vec::new();
                let mut d_slot = Vec::new();
                for (k, &s) in samples.iter().enumerate() {
                    if s < f64::from(threshold) {
                        i_slot.push(s);
                        d_slot.push(set.phase_shifts_rad[k]);
                    }
                }
                if i_slot.len() < 3 {
                    continue;
                }
                let mut a = nalgebra::Matrix3::<f64>::zeros();
                let mut b = nalgebra::Vector3::<f64>::zeros();
                for (&s, &d) in i_slot.iter().zip(&d_slot) {
                    let row = nalgebra::Vector3::new(1.0, d.cos(), d.sin());
                    a += row * row.transpose();
                    b += row * s;
                }
                let Some(c) = a.try_inverse() else { continue };
                let x = c * b;
                if x[1].hypot(x[2]) >= min_modulation {
                    phi[m][i] = (-x[2]).atan2(x[1]).rem_euclid(std::f64::consts::TAU);
                }
            }
        }
    }
    // Alg. 3, first loop.
    let mut unwrapped = vec![vec![f64::NAN; len]; m_count];
    unwrapped[0] = phi[0].clone();
    for m in 1..m_count {
        for i in 0..len {
            let ratio = sets[m - 1].period_px / sets[m].period_px;
            let k = ((unwrapped[m - 1][i] * ratio - phi[m][i]) / std::f64::consts::TAU).round();
            unwrapped[m][i] = phi[m][i] + std::f64::consts::TAU * k;
        }
    }
    // Alg. 3, replacement loops.
    let densest = sets[m_count - 1].period_px;
    let mut fused = vec![f64::NAN; len];
    let mut source = vec![-1i8; len];
    for m in 0..m_count {
        let n = sets[m].shifts();
        for i in 0..len {
            let denser_over = (m + 1..m_count).all(|d| sat_map[d][i] > sets[d].shifts() - 3);
            if denser_over && sat_map[m][i] <= n - 3 && !unwrapped[m][i].is_nan() {
                fused[i] = unwrapped[m][i] * sets[m].period_px / densest;
                source[i] = m as i8;
            }
        }
    }
    BaselineCamera { fused_phase_rad: fused, source_set: source }
}
