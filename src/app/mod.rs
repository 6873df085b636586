//! The egui/eframe inspection application over the engine.
