//! The catalogue of scenes: each builder lays out one object on the stage
//! (field about 23.9 x 17.9 mm centred on the origin) with its materials,
//! its projector focus, its exposure and the landmarks accuracy tests check.
//!
//! Exposures and gloss are tuned so the shiny scenes hold, side by side,
//! pixels that are partially saturated, pixels over-saturated only with the
//! densest fringes and pixels over-saturated with several periods (the
//! situations of the paper's Figs. 2 and 5); the metrology artefacts are
//! exposed to stay unsaturated.

use super::material::{Brush, Material};
use super::scene_model::{Feature, Footprint, Landmark, Region, RingDent, Scene, SceneKind, Surface, thread_depth_mm};

/// Builds the scene of `kind`.
pub fn build(kind: SceneKind) -> Scene {
    match kind {
        SceneKind::WatchPlate => watch_plate(),
        SceneKind::Gaskets => gaskets(),
        SceneKind::Pcb => pcb(),
        SceneKind::ScrewThread => screw_thread(),
        SceneKind::Flat => flat(),
        SceneKind::StepGauge => step_gauge(),
        SceneKind::Sphere => sphere(),
        SceneKind::DimPart => dim_part(),
    }
}

fn feature(name: &str, footprint: Footprint, surface: Surface, material: usize) -> Feature {
    Feature { name: name.to_owned(), footprint, surface, material }
}

fn level(z_mm: f64) -> Surface {
    Surface::Plane { z0_mm: z_mm, slope_x: 0.0, slope_y: 0.0 }
}

fn rect(cx: f64, cy: f64, hx: f64, hy: f64, corner: f64) -> Footprint {
    Footprint::Rect { center_mm: [cx, cy], half_size_mm: [hx, hy], corner_radius_mm: corner }
}

fn disc(cx: f64, cy: f64, r: f64) -> Footprint {
    Footprint::Disc { center_mm: [cx, cy], radius_mm: r }
}

fn region(x_min: f64, x_max: f64, y_min: f64, y_max: f64) -> Region {
    Region { x_min_mm: x_min, x_max_mm: x_max, y_min_mm: y_min, y_max_mm: y_max }
}

fn land(name: &str, r: Region, height_mm: f64) -> Landmark {
    Landmark::Land { name: name.to_owned(), region: r, height_mm }
}

fn brush(direction_deg: f64, gloss_variation: f64, along_mm: f64, across_mm: f64, tilt_rad: f64) -> Option<Brush> {
    Some(Brush { direction_deg, gloss_variation, along_mm, across_mm, tilt_rad })
}

/// Nickel-plated watch plate (the paper's Fig. 6): a brushed plate with two
/// lands, two pockets, a raised boss carrying a bore, a domed pillar and a
/// jewel hole.
fn watch_plate() -> Scene {
    let materials = vec![
        Material::glossy("brushed nickel", 0.22, 2.6, 45.0, brush(90.0, 3.0, 1.5, 0.05, 0.07)),
        Material::glossy("lapped nickel", 0.25, 3.2, 70.0, brush(20.0, 2.5, 2.5, 0.08, 0.05)),
        Material::glossy("milled nickel", 0.25, 1.6, 18.0, brush(0.0, 2.0, 0.6, 0.12, 0.10)),
        Material::glossy("bore floor", 0.08, 0.3, 10.0, None),
    ];
    let (brushed, lapped, milled, dark) = (0, 1, 2, 3);
    let features = vec![
        feature("plate", Footprint::All, level(0.0), brushed),
        feature("upper land", rect(-6.0, 3.5, 4.5, 3.5, 1.0), level(0.30), lapped),
        feature("lower land", rect(5.5, -4.5, 5.0, 3.0, 1.2), level(0.15), lapped),
        feature("pocket", rect(-6.5, -5.0, 3.0, 2.2, 0.6), level(-0.25), milled),
        feature("round pocket", disc(-1.5, 5.8, 1.6), level(-0.12), milled),
        feature("boss", disc(5.0, 3.5, 2.6), level(0.60), lapped),
        feature("bore", disc(5.0, 3.5, 1.1), level(-1.0), dark),
        feature("jewel hole", disc(-7.5, 4.5, 0.5), level(-0.5), dark),
        feature(
            "domed pillar",
            disc(-1.0, -2.0, 0.9),
            Surface::SphereCap { center_mm: [-1.0, -2.0, 0.45 - 6.0], radius_mm: 6.0 },
            lapped,
        ),
    ];
    let landmarks = vec![
        land("plate", region(-0.5, 2.5, -0.5, 1.5), 0.0),
        land("upper land", region(-6.8, -3.4, 0.8, 6.2), 0.30),
        land("lower land", region(2.0, 9.5, -6.5, -2.5), 0.15),
        land("pocket", region(-8.5, -4.5, -6.5, -3.5), -0.25),
        land("boss top", region(6.4, 7.2, 3.1, 3.9), 0.60),
        Landmark::Step {
            name: "upper land above plate".into(),
            reference: region(-0.5, 2.5, -0.5, 1.5),
            measured: region(-6.8, -3.4, 0.8, 6.2),
            height_mm: 0.30,
        },
        Landmark::Step {
            name: "boss above lower land".into(),
            reference: region(2.0, 9.5, -6.5, -2.5),
            measured: region(6.4, 7.2, 3.1, 3.9),
            height_mm: 0.45,
        },
        Landmark::Bore { name: "bore".into(), center_mm: [5.0, 3.5], radius_mm: 1.1, floor_mm: -1.0 },
        Landmark::Sphere { name: "domed pillar".into(), center_mm: [-1.0, -2.0, 0.45 - 6.0], radius_mm: 6.0 },
        Landmark::Section { name: "through boss and bore".into(), from_mm: [-11.0, 3.5], to_mm: [11.0, 3.5] },
    ];
    Scene::new(
        SceneKind::WatchPlate,
        "nickel-plated watch plate with lands, pockets, a bore in a raised boss; brushed",
        materials,
        features,
        landmarks,
        0.2,
        0.55,
    )
}

/// Two steel gaskets (the paper's Fig. 7): the upper one as made, the lower
/// one bent by load (lower in the middle, higher at both ends) with a circular
/// indentation around its centre.
fn gaskets() -> Scene {
    let materials = vec![
        Material::matte("black anodised stage", 0.05),
        Material::glossy("ground steel", 0.28, 2.4, 35.0, brush(75.0, 3.0, 1.2, 0.05, 0.08)),
    ];
    let (stage, steel) = (0, 1);
    let (half_x, half_y, cy) = (10.5, 3.3, 4.3);
    let rise_at_ends_mm = 0.06;
    let curvature = 2.0 * rise_at_ends_mm / (half_x * half_x);
    let dent = RingDent { center_mm: [0.0, -cy], radius_mm: 2.2, width_mm: 0.18, depth_mm: 0.025 };
    let features = vec![
        feature("stage", Footprint::All, level(0.0), stage),
        feature("flat gasket", rect(0.0, cy, half_x, half_y, 1.2), level(0.5), steel),
        feature("flat gasket left hole", disc(-6.5, cy, 1.3), level(0.0), stage),
        feature("flat gasket right hole", disc(6.5, cy, 1.3), level(0.0), stage),
        feature(
            "loaded gasket",
            rect(0.0, -cy, half_x, half_y, 1.2),
            Surface::Bent { z0_mm: 0.47, center_x_mm: 0.0, curvature_per_mm: curvature, dent: Some(dent) },
            steel,
        ),
        feature("loaded gasket left hole", disc(-6.5, -cy, 1.3), level(0.0), stage),
        feature("loaded gasket right hole", disc(6.5, -cy, 1.3), level(0.0), stage),
    ];
    let landmarks = vec![
        Landmark::Plane {
            name: "flat gasket".into(),
            z0_mm: 0.5,
            slope_x: 0.0,
            slope_y: 0.0,
            region: region(-4.5, 4.5, 2.0, 6.6),
        },
        Landmark::Step {
            name: "flat gasket thickness".into(),
            reference: region(-10.0, 10.0, -0.6, 0.6),
            measured: region(-4.5, 4.5, 2.0, 6.6),
            height_mm: 0.5,
        },
        Landmark::Section { name: "vertical section A".into(), from_mm: [-3.0, 8.5], to_mm: [-3.0, -8.5] },
        Landmark::Section { name: "vertical section B".into(), from_mm: [3.0, 8.5], to_mm: [3.0, -8.5] },
        Landmark::Section { name: "flat gasket section".into(), from_mm: [-10.0, 6.3], to_mm: [10.0, 6.3] },
        Landmark::Section { name: "loaded gasket section".into(), from_mm: [-10.0, -2.8], to_mm: [10.0, -2.8] },
    ];
    Scene::new(
        SceneKind::Gaskets,
        "two steel gaskets: one as made, one bent by load with a circular indentation",
        materials,
        features,
        landmarks,
        0.5,
        0.7,
    )
}

/// Seven-segment strokes of `text` (digits and the letters A b C d E F H J L P U),
/// each character `height` tall with its lower left corner at `origin`.
fn seven_segment(text: &str, origin: [f64; 2], height: f64, stroke: f64) -> Vec<Footprint> {
    let w = 0.6 * height;
    let h2 = height / 2.0;
    let mut out = Vec::new();
    for (i, ch) in text.chars().enumerate() {
        let segments = match ch {
            '0' => "abcdef",
            '1' | 'I' => "bc",
            '2' => "abdeg",
            '3' => "abcdg",
            '4' => "bcfg",
            '5' => "acdfg",
            '6' => "acdefg",
            '7' => "abc",
            '8' => "abcdefg",
            '9' => "abcdfg",
            'A' => "abcefg",
            'b' => "cdefg",
            'C' => "adef",
            'd' => "bcdeg",
            'E' => "adefg",
            'F' => "aefg",
            'H' => "bcefg",
            'J' => "bcde",
            'L' => "def",
            'P' => "abefg",
            'U' => "bcdef",
            _ => "",
        };
        let x0 = origin[0] + i as f64 * (w + 0.35 * height);
        let y0 = origin[1];
        for s in segments.chars() {
            let (cx, cy, hx, hy) = match s {
                'a' => (x0 + w / 2.0, y0 + height, w / 2.0, stroke / 2.0),
                'b' => (x0 + w, y0 + 1.5 * h2, stroke / 2.0, h2 / 2.0),
                'c' => (x0 + w, y0 + 0.5 * h2, stroke / 2.0, h2 / 2.0),
                'd' => (x0 + w / 2.0, y0, w / 2.0, stroke / 2.0),
                'e' => (x0, y0 + 0.5 * h2, stroke / 2.0, h2 / 2.0),
                'f' => (x0, y0 + 1.5 * h2, stroke / 2.0, h2 / 2.0),
                _ => (x0 + w / 2.0, y0 + h2, w / 2.0, stroke / 2.0),
            };
            out.push(rect(cx, cy, hx + stroke / 2.0, hy + stroke / 2.0, 0.0));
        }
    }
    out
}

/// A circuit board (the paper's Fig. 5e): tin pads (a QFP land pattern around
/// its chip, 0805 pad pairs, a ball grid, a ground bar, vias) and white
/// silkscreen outlines and labels on green solder mask.
fn pcb() -> Scene {
    let materials = vec![
        Material::glossy("green solder mask", 0.12, 0.25, 12.0, None),
        Material::glossy("tin (HASL)", 0.35, 2.8, 30.0, brush(0.0, 3.0, 0.25, 0.12, 0.12)),
        Material::glossy("white silkscreen", 0.8, 0.05, 5.0, None),
        Material::glossy("black epoxy", 0.05, 0.4, 20.0, None),
        Material::matte("via hole", 0.02),
    ];
    let (mask, tin, silk, epoxy, hole) = (0, 1, 2, 3, 4);
    let pad_z = 0.05;
    let silk_z = 0.025;
    let mut features = vec![feature("board", Footprint::All, level(0.0), mask)];
    let mut landmarks = Vec::new();

    // QFP: 4 x 10 pads at 0.65 mm pitch around a 5 x 5 mm body.
    let (qx, qy) = (-5.0, 1.5);
    for k in 0..10 {
        let t = (k as f64 - 4.5) * 0.65;
        for (name, cx, cy, hx, hy) in [
            ("qfp top pad", qx + t, qy + 3.6, 0.15, 0.6),
            ("qfp bottom pad", qx + t, qy - 3.6, 0.15, 0.6),
            ("qfp left pad", qx - 3.6, qy + t, 0.6, 0.15),
            ("qfp right pad", qx + 3.6, qy + t, 0.6, 0.15),
        ] {
            features.push(feature(name, rect(cx, cy, hx, hy, 0.0), level(pad_z), tin));
        }
    }
    features.push(feature("qfp body", rect(qx, qy, 2.5, 2.5, 0.2), level(1.2), epoxy));
    // 0805 pad pairs.
    for (i, (cx, cy)) in [(4.0, 5.5), (4.0, 2.0), (8.0, 5.5), (8.0, 2.0)].into_iter().enumerate() {
        for dx in [-1.0, 1.0] {
            features.push(feature(&format!("0805 pad {i}"), rect(cx + dx, cy, 0.5, 0.65, 0.05), level(pad_z), tin));
        }
    }
    // Ball grid pads.
    for r in 0..5 {
        for c in 0..5 {
            let (cx, cy) = (4.4 + c as f64 * 0.8, -6.6 + r as f64 * 0.8);
            features.push(feature("bga pad", disc(cx, cy, 0.25), level(pad_z), tin));
        }
    }
    // Ground bar.
    features.push(feature("ground bar", rect(-4.5, -6.8, 5.0, 1.0, 0.3), level(pad_z), tin));
    landmarks.push(Landmark::Step {
        name: "ground bar above mask".into(),
        reference: region(-9.0, 0.0, -8.6, -8.1),
        measured: region(-9.0, 0.0, -7.4, -6.2),
        height_mm: pad_z,
    });
    // Vias: tin rings around dark holes.
    for i in 0..5 {
        let (cx, cy) = (-9.5 + i as f64 * 1.6, 7.6);
        features.push(feature(
            "via ring",
            Footprint::Annulus { center_mm: [cx, cy], inner_radius_mm: 0.0, outer_radius_mm: 0.45 },
            level(pad_z),
            tin,
        ));
        features.push(feature("via hole", disc(cx, cy, 0.2), level(-1.6), hole));
    }
    // Silkscreen: QFP outline, 0805 outlines, labels.
    let stroke = 0.15;
    for (cx, cy, hx, hy) in [
        (qx, qy + 4.5, 4.5, stroke / 2.0),
        (qx, qy - 4.5, 4.5, stroke / 2.0),
        (qx - 4.5, qy, stroke / 2.0, 4.5),
        (qx + 4.5, qy, stroke / 2.0, 4.5),
    ] {
        features.push(feature("silkscreen outline", rect(cx, cy, hx, hy, 0.0), level(silk_z), silk));
    }
    for (cx, cy) in [(4.0, 5.5), (4.0, 2.0), (8.0, 5.5), (8.0, 2.0)] {
        for dy in [-1.0, 1.0] {
            features.push(feature("silkscreen 0805", rect(cx, cy + dy, 1.7, stroke / 2.0, 0.0), level(silk_z), silk));
        }
    }
    for (text, origin) in [("U1", [qx - 1.0, qy + 5.0]), ("C1", [3.3, 7.0]), ("C2", [7.3, 7.0]), ("J1", [5.5, -3.8])] {
        for fp in seven_segment(text, origin, 1.0, 0.14) {
            features.push(feature(&format!("silkscreen {text}"), fp, level(silk_z), silk));
        }
    }
    landmarks.push(land("solder mask", region(0.5, 2.5, -3.0, 0.0), 0.0));
    landmarks.push(land("qfp body top", region(qx - 2.0, qx + 2.0, qy - 2.0, qy + 2.0), 1.2));
    Scene::new(
        SceneKind::Pcb,
        "circuit board: tin pads and white silkscreen on green solder mask",
        materials,
        features,
        landmarks,
        0.3,
        0.6,
    )
}

/// An M5-like threaded rod (pitch 0.8 mm) with a plain shank, lying on the stage.
fn screw_thread() -> Scene {
    let materials = vec![
        Material::matte("dark stage", 0.06),
        Material::glossy("turned steel", 0.25, 3.0, 20.0, brush(90.0, 2.5, 1.0, 0.03, 0.05)),
    ];
    let (stage, steel) = (0, 1);
    let (major, pitch, axis_z) = (2.5, 0.8, 0.1);
    let stage_z = axis_z - major;
    let features = vec![
        feature("stage", Footprint::All, level(stage_z), stage),
        feature(
            "thread",
            rect(-1.5, 0.0, 10.0, major, 0.0),
            Surface::Thread {
                axis_y_mm: 0.0,
                axis_z_mm: axis_z,
                major_radius_mm: major,
                pitch_mm: pitch,
                start_x_mm: 0.0,
            },
            steel,
        ),
        feature(
            "shank",
            rect(9.75, 0.0, 1.25, major, 0.0),
            Surface::Cylinder { axis_y_mm: 0.0, axis_z_mm: axis_z, radius_mm: major },
            steel,
        ),
    ];
    let landmarks = vec![
        Landmark::Thread {
            name: "thread".into(),
            pitch_mm: pitch,
            major_radius_mm: major,
            minor_radius_mm: major - thread_depth_mm(pitch),
            axis_y_mm: 0.0,
            axis_z_mm: axis_z,
        },
        Landmark::Section { name: "thread crest line".into(), from_mm: [-11.0, 0.0], to_mm: [8.0, 0.0] },
        land("stage", region(-10.0, 10.0, -8.5, -4.0), stage_z),
    ];
    Scene::new(
        SceneKind::ScrewThread,
        "threaded steel rod (pitch 0.8 mm) lying on the stage",
        materials,
        features,
        landmarks,
        1.6,
        1.5,
    )
}

/// A lapped flat, tilted by 1.5 mrad in X and -1 mrad in Y.
fn flat() -> Scene {
    let (z0, sx, sy) = (0.1, 0.0015, -0.001);
    let materials = vec![Material::glossy("lapped steel", 0.45, 0.35, 8.0, None)];
    let features = vec![feature("flat", Footprint::All, Surface::Plane { z0_mm: z0, slope_x: sx, slope_y: sy }, 0)];
    let landmarks = vec![Landmark::Plane {
        name: "flat".into(),
        z0_mm: z0,
        slope_x: sx,
        slope_y: sy,
        region: region(-11.0, 11.0, -8.0, 8.0),
    }];
    Scene::new(SceneKind::Flat, "lapped steel flat, slightly tilted", materials, features, landmarks, 0.1, 0.9)
}

/// Step heights of the step gauge, micrometres.
pub const STEP_GAUGE_HEIGHTS_UM: [f64; 4] = [10.0, 50.0, 200.0, 500.0];

/// A gauge base with four blocks of 10, 50, 200 and 500 um, walls along Y so
/// they face the cameras (and occlude the base beside them for one camera).
fn step_gauge() -> Scene {
    let materials = vec![Material::glossy("gauge steel", 0.4, 0.3, 10.0, None)];
    let mut features = vec![feature("base", Footprint::All, level(0.0), 0)];
    let mut landmarks = vec![land("base", region(-11.0, 11.0, -8.5, -7.5), 0.0)];
    let half_x = 1.8;
    for (i, h_um) in STEP_GAUGE_HEIGHTS_UM.into_iter().enumerate() {
        let cx = -8.0 + 5.5 * i as f64;
        let name = format!("step {h_um} um");
        features.push(feature(&name, rect(cx, 0.0, half_x, 6.5, 0.0), level(h_um * 1e-3), 0));
        landmarks.push(Landmark::Step {
            name,
            reference: region(cx - half_x - 1.5, cx - half_x - 0.4, -5.0, 5.0),
            measured: region(cx - half_x + 0.5, cx + half_x - 0.5, -5.0, 5.0),
            height_mm: h_um * 1e-3,
        });
    }
    Scene::new(
        SceneKind::StepGauge,
        "step gauge: blocks of 10, 50, 200 and 500 um on a base",
        materials,
        features,
        landmarks,
        0.25,
        0.9,
    )
}

/// A ceramic ball of radius 4 mm sunk into a plate so a 1.5 mm cap stands out.
fn sphere() -> Scene {
    let (radius, center): (f64, [f64; 3]) = (4.0, [0.0, 0.0, -2.5]);
    let rim = (radius * radius - center[2] * center[2]).sqrt();
    let materials = vec![
        Material::glossy("ceramic plate", 0.5, 0.2, 8.0, None),
        Material::glossy("ceramic ball", 0.6, 0.3, 10.0, None),
    ];
    let features = vec![
        feature("plate", Footprint::All, level(0.0), 0),
        feature(
            "ball",
            disc(center[0], center[1], rim),
            Surface::SphereCap { center_mm: center, radius_mm: radius },
            1,
        ),
    ];
    let landmarks = vec![
        Landmark::Sphere { name: "ball".into(), center_mm: center, radius_mm: radius },
        land("plate", region(-11.0, 11.0, -8.5, -6.0), 0.0),
    ];
    Scene::new(SceneKind::Sphere, "ceramic sphere of radius 4 mm on a plate", materials, features, landmarks, 0.75, 0.8)
}

/// Modulation of the dim part's matte tiles under the camera-projector
/// preset (gain 0.5, 8 bits), grey levels, and the heights of the tiles.
pub const DIM_TILE_MODULATION_DN: [f64; 4] = [4.0, 6.0, 9.0, 12.0];
const DIM_TILE_HEIGHTS_MM: [f64; 4] = [0.30, 0.10, 0.20, 0.40];

/// A bright painted part (a block with a boss) on black cloth, with four
/// matte tiles and a tilted ramp so dim that they carry 4-12 DN of
/// modulation: the faces of a real part that turn away from the light.
fn dim_part() -> Scene {
    // Modulation B = full scale x exposure x gain x m / 2 x albedo: with the
    // preset's gain 0.5 and m = 0.95, an albedo of 1 gives 60.6 DN.
    let albedo_for = |dn: f64| dn / (255.0 * 0.5 * 0.5 * 0.95);
    let mut materials = vec![
        Material::matte("black cloth", 0.03),
        Material::glossy("painted part", 0.8, 0.4, 6.0, None),
        Material::matte("dim ramp", albedo_for(8.0)),
    ];
    let (cloth, part, ramp) = (0, 1, 2);
    let mut features = vec![
        feature("cloth", Footprint::All, level(0.0), cloth),
        feature("part", rect(0.0, 0.5, 4.5, 3.5, 0.8), level(1.2), part),
        feature("boss", disc(1.5, 1.0, 1.5), level(1.8), part),
        feature(
            "dim ramp",
            rect(0.0, -6.3, 4.0, 1.3, 0.0),
            Surface::Plane { z0_mm: 0.4, slope_x: 0.1, slope_y: 0.0 },
            ramp,
        ),
    ];
    let mut landmarks = vec![land("part top", region(-3.5, -0.5, -2.0, 3.0), 1.2)];
    let centres = [[-8.0, 4.0], [-8.0, -4.0], [8.0, 4.0], [8.0, -4.0]];
    for (i, (&dn, &z)) in DIM_TILE_MODULATION_DN.iter().zip(&DIM_TILE_HEIGHTS_MM).enumerate() {
        let name = format!("{dn} DN tile");
        materials.push(Material::matte(&name, albedo_for(dn)));
        let [cx, cy] = centres[i];
        features.push(feature(&name, rect(cx, cy, 2.6, 2.8, 0.0), level(z), 3 + i));
        landmarks.push(land(&name, region(cx - 2.0, cx + 2.0, cy - 2.2, cy + 2.2), z));
    }
    Scene::new(
        SceneKind::DimPart,
        "bright painted part on black cloth beside matte faces with 4-12 DN of modulation",
        materials,
        features,
        landmarks,
        0.6,
        1.0,
    )
}
