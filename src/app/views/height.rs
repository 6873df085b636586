//! Top view of the point cloud: the height Z of each 3D point drawn at the
//! left-camera pixel it was measured at, with a colour bar in micrometres and
//! an adjustable range (the paper's Fig. 6(c) as a map).

use eframe::egui;

use crate::app::commands::Command;
use crate::app::palette::{self, Colormap};
use crate::app::run_data::ResultSet;
use crate::app::textures::key_of;
use crate::app::widgets::legend::Legend;

use super::{
    MapSpec, Pane, RangeSetting, View, ViewCx, colormap_picker, format_value, paint_continuous, percent, robust_range,
};

#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct HeightView {
    pub colormap: Colormap,
    pub range: RangeSetting,
}

/// The camera the cloud is organized on: the main (left) camera.
const CLOUD_CAMERA: usize = 0;

fn auto_range(cx: &ViewCx<'_>) -> Option<(f32, f32)> {
    let heights = |r: &ResultSet| r.derived.height.as_deref().and_then(|h| robust_range(h, 0.01, 0.99));
    cx.memo_range("height", || cx.result.and_then(heights))
}

impl View for HeightView {
    fn controls(&mut self, ui: &mut egui::Ui, cx: &ViewCx<'_>) {
        colormap_picker(ui, "height colormap", &mut self.colormap);
        let unit = cx.result.map_or("µm", |r| r.derived.height_unit.as_str()).to_owned();
        self.range.ui(ui, &unit, auto_range(cx));
    }

    fn panes<'a>(&self, cx: &ViewCx<'a>, _cameras: &[usize], _commands: &mut Vec<Command>) -> Vec<Pane<'a>> {
        let camera = CLOUD_CAMERA;
        let title = format!("{} · height of the 3D points", cx.camera_name(camera));
        let Some(result) = cx.result else {
            return vec![Pane::message(camera, title, "No result yet: the engine is running or has not run.")];
        };
        let rec = &result.reconstruction;
        let (Some(cloud), Some(height)) = (rec.cloud(), result.derived.height.as_ref()) else {
            let why = rec.stereo_skipped.as_deref().unwrap_or("no stereo result");
            return vec![Pane::message(camera, title, format!("No 3D points: {why}."))];
        };
        let unit = result.derived.height_unit.as_str();
        let auto = auto_range(cx);
        let (lo, hi) = self.range.resolve(auto);
        let size = [cloud.grid_width, cloud.grid_height];
        let map = self.colormap;
        let key = key_of(&("height", cx.generation(), map, self.range.key(auto)));
        let paint = Box::new(move || paint_continuous(height, size, palette::lut(map), lo, hi));
        let probe = Box::new(move |p: usize| {
            let z = height[p];
            if z.is_finite() { format!("Z = {}", format_value(z, unit)) } else { "no 3D point".to_owned() }
        });
        let legend =
            Legend::bar(palette::lut(map), f64::from(lo), f64::from(hi), unit).with_entry(palette::INVALID, "no point");
        let points = format!("{} points ({} of the pixels)", cloud.len(), percent(cloud.len(), size[0] * size[1]));
        let footer = Some(match rec.stereo.as_ref() {
            Some(stereo) => {
                let s = &stereo.match_stats;
                format!("{points} · unmatched {} · ambiguous {}", s.unmatched, s.ambiguous)
            }
            // A camera–projector rig's cloud: seen from the camera, Z towards it.
            None => format!("{points} · from the projector coordinates, Z towards the camera"),
        });
        vec![Pane::map(camera, title, MapSpec { size, key, paint, probe, legend, footer })]
    }
}
