//! The persisted part of the app: operator parameters, theme, recent files,
//! panel layout and every view's settings. Serialized by eframe between
//! sessions; runtime resources (measurement, results, textures, jobs) live in
//! [`super::SheenApp`] and are never persisted.

use std::path::{Path, PathBuf};

use eframe::egui;

use crate::engine::fringe::Measurement;
use crate::engine::pipeline::Params;

use super::panels::log::LogFilter;
use super::views::ViewsState;

/// At most this many recent files are remembered.
pub const MAX_RECENT_FILES: usize = 10;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Theme {
    #[default]
    Dark,
    Light,
    /// Follow the operating system.
    System,
}

impl Theme {
    pub const ALL: [Theme; 3] = [Theme::Dark, Theme::Light, Theme::System];

    pub fn name(self) -> &'static str {
        match self {
            Theme::Dark => "Dark",
            Theme::Light => "Light",
            Theme::System => "Follow system",
        }
    }

    pub fn preference(self) -> egui::ThemePreference {
        match self {
            Theme::Dark => egui::ThemePreference::Dark,
            Theme::Light => egui::ThemePreference::Light,
            Theme::System => egui::ThemePreference::System,
        }
    }
}

/// Which camera(s) the views show.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum CameraLayout {
    /// The first camera (the main, left camera of a stereo rig).
    #[default]
    Main,
    /// The second camera.
    Second,
    /// Both, side by side.
    SideBySide,
}

impl CameraLayout {
    /// Camera indices to show, for a measurement with `cameras` cameras.
    pub fn cameras(self, cameras: usize) -> Vec<usize> {
        match (self, cameras) {
            (_, 0) => Vec::new(),
            (CameraLayout::Main, _) | (_, 1) => vec![0],
            (CameraLayout::Second, _) => vec![1],
            (CameraLayout::SideBySide, _) => vec![0, 1],
        }
    }
}

/// The tab shown in the right-hand panel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SideTab {
    #[default]
    Inspector,
    Statistics,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct Layout {
    pub show_log: bool,
    pub show_side_panel: bool,
    pub side_tab: SideTab,
    pub log_filter: LogFilter,
}

impl Default for Layout {
    fn default() -> Self {
        Self { show_log: true, show_side_panel: true, side_tab: SideTab::Inspector, log_filter: LogFilter::default() }
    }
}

/// Everything remembered between sessions.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct AppState {
    pub params: Params,
    /// Re-run the engine automatically when a parameter changes.
    pub auto_run: bool,
    pub theme: Theme,
    /// Most recent first.
    pub recent_files: Vec<PathBuf>,
    pub layout: Layout,
    pub views: ViewsState,
}

impl Default for AppState {
    fn default() -> Self {
        Self {
            params: Params::default(),
            auto_run: true,
            theme: Theme::Dark,
            recent_files: Vec::new(),
            layout: Layout::default(),
            views: ViewsState::default(),
        }
    }
}

impl AppState {
    /// Puts `path` first in the recent-files list (once), dropping the oldest beyond the limit.
    pub fn remember_file(&mut self, path: &Path) {
        self.recent_files.retain(|p| p != path);
        self.recent_files.insert(0, path.to_path_buf());
        self.recent_files.truncate(MAX_RECENT_FILES);
    }

    pub fn forget_file(&mut self, path: &Path) {
        self.recent_files.retain(|p| p != path);
    }
}

/// Largest grey level of a bit depth (`2^bits - 1`, at most `u16::MAX`).
pub fn max_dn(bit_depth: u32) -> u16 {
    if bit_depth >= 16 { u16::MAX } else { ((1u32 << bit_depth.max(1)) - 1) as u16 }
}

/// Makes remembered parameters valid for a newly loaded measurement and says
/// what it changed: the enabled-set list must have one entry per set (a
/// different set count resets it to all enabled), the threshold must lie in
/// the bit depth's range, the modulation floor must be finite and >= 0.
pub fn fit_params_to(params: &mut Params, m: &Measurement) -> Vec<String> {
    let mut notes = Vec::new();
    if !params.enabled_sets.is_empty() && params.enabled_sets.len() != m.sets.len() {
        notes.push(format!(
            "the remembered set selection was for {} sets; this measurement has {}, so all sets are enabled",
            params.enabled_sets.len(),
            m.sets.len()
        ));
        params.enabled_sets.clear();
    }
    if params.enabled_sets.is_empty() {
        params.enabled_sets = vec![true; m.sets.len()];
    }
    let top = max_dn(m.bit_depth);
    if let Some(t) = params.saturation_threshold
        && (t == 0 || t > top)
    {
        notes.push(format!(
            "the remembered saturation threshold {t} dn is outside 1..={top} dn for {}-bit data; using the saturation level {} dn",
            m.bit_depth, m.saturation_level
        ));
        params.saturation_threshold = None;
    }
    if !params.min_modulation_dn.is_finite() || params.min_modulation_dn < 0.0 {
        params.min_modulation_dn = Params::default().min_modulation_dn;
    }
    if params.min_modulation_dn > f32::from(top) {
        notes.push(format!(
            "the remembered minimum modulation {} dn exceeds the {}-bit range; reset to {} dn",
            params.min_modulation_dn,
            m.bit_depth,
            Params::default().min_modulation_dn
        ));
        params.min_modulation_dn = Params::default().min_modulation_dn;
    }
    notes
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::fringe::{FringeSetInfo, next_measurement_id};

    fn measurement(bits: u32, sets: usize) -> Measurement {
        Measurement {
            bit_depth: bits,
            saturation_level: max_dn(bits),
            sets: (0..sets).map(|s| FringeSetInfo::uniform(100.0 / (s + 1) as f64, 4)).collect(),
            cameras: Vec::new(),
            calibration: None,
            label: "test".into(),
            projector: None,
            id: next_measurement_id(),
        }
    }

    #[test]
    fn max_dn_follows_the_bit_depth() {
        assert_eq!(max_dn(8), 255);
        assert_eq!(max_dn(10), 1023);
        assert_eq!(max_dn(12), 4095);
        assert_eq!(max_dn(16), 65535);
    }

    #[test]
    fn params_from_a_16_bit_session_are_fitted_to_8_bit_data() {
        let mut p = Params { saturation_threshold: Some(4000), enabled_sets: vec![true, false], ..Params::default() };
        let notes = fit_params_to(&mut p, &measurement(8, 3));
        assert_eq!(p.saturation_threshold, None);
        assert_eq!(p.enabled_sets, vec![true; 3]);
        assert_eq!(notes.len(), 2, "{notes:?}");
    }

    #[test]
    fn matching_params_are_kept() {
        let mut p =
            Params { saturation_threshold: Some(250), enabled_sets: vec![true, false, true], ..Params::default() };
        let before = p.clone();
        assert!(fit_params_to(&mut p, &measurement(8, 3)).is_empty());
        assert_eq!(p, before);
    }

    #[test]
    fn recent_files_are_unique_newest_first_and_bounded() {
        let mut s = AppState::default();
        for i in 0..MAX_RECENT_FILES + 3 {
            s.remember_file(Path::new(&format!("/m/{i}.json")));
        }
        s.remember_file(Path::new("/m/5.json"));
        assert_eq!(s.recent_files.len(), MAX_RECENT_FILES);
        assert_eq!(s.recent_files[0], Path::new("/m/5.json"));
        assert_eq!(s.recent_files.iter().filter(|p| p.as_path() == Path::new("/m/5.json")).count(), 1);
    }

    #[test]
    fn state_survives_a_json_round_trip() {
        let mut s = AppState::default();
        s.remember_file(Path::new("/data/run1/manifest.json"));
        s.params.min_modulation_dn = 7.5;
        s.theme = Theme::Light;
        let text = serde_json::to_string(&s).expect("serialize");
        let back: AppState = serde_json::from_str(&text).expect("deserialize");
        assert_eq!(back, s);
    }
}
