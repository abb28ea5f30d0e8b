//! The viewer's panel: the method (typed, or one of the keyed families),
//! the animation, the lighting, the exposure, the heat map, and where each
//! frame's time goes.

use shadow_core::{ProfileValue, Stage};

use super::{
    state::{Heat, ViewState},
    window::KEYED_METHODS,
};

/// The panel's own state: the method name being typed.
pub struct Panel {
    pub name: String,
}

impl Panel {
    pub fn new(method: &str) -> Panel {
        Panel {
            name: method.to_string(),
        }
    }

    pub fn show(&mut self, ui: &mut egui::Ui, state: &mut ViewState) {
        // At the top right, so that the scene, centred, stays in view.
        egui::Window::new("harness view")
            .anchor(egui::Align2::RIGHT_TOP, [-8.0, 8.0])
            .default_width(300.0)
            .resizable(false)
            .show(ui.ctx(), |ui| self.contents(ui, state));
    }

    fn contents(&mut self, ui: &mut egui::Ui, state: &mut ViewState) {
        ui.label(format!("{} · {}", state.scene().name(), state.adapter()));
        ui.horizontal(|ui| {
            ui.label("method");
            let field = ui.text_edit_singleline(&mut self.name);
            if field.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter)) {
                self.apply(state);
            }
        });
        ui.horizontal_wrapped(|ui| {
            for (key, name) in KEYED_METHODS.iter().enumerate() {
                if ui.button(format!("{} {name}", key + 1)).clicked() {
                    self.name = name.to_string();
                    self.apply(state);
                }
            }
        });
        if let Some(error) = &state.error {
            ui.colored_label(egui::Color32::LIGHT_RED, error);
        }
        ui.separator();

        let frames = state.scene().frames().len();
        if frames > 1 {
            ui.horizontal(|ui| {
                let play = if state.playing { "pause" } else { "play" };
                if ui.button(play).clicked() {
                    state.playing = !state.playing;
                }
                let mut result = Ok(());
                if ui.button("<").clicked() {
                    result = state.step(-1);
                }
                if ui.button(">").clicked() {
                    result = state.step(1);
                }
                ui.label(format!("frame {} of {frames}", state.frame_index() + 1));
                if let Err(e) = result {
                    state.error = Some(e.to_string());
                }
            });
        }
        let mut turn = state.turn();
        if ui
            .add(egui::Slider::new(&mut turn, 0.0..=359.0).text("environment turn (°)"))
            .changed()
        {
            state.set_turn(turn);
        }
        ui.add(egui::Slider::new(&mut state.exposure_ev, -8.0..=8.0).text("exposure (EV)"));
        ui.checkbox(&mut state.heat_map, "error heat map (H)");
        match state.heat() {
            Some(Heat::Error(e)) => {
                ui.label(format!(
                    "relative L2 error against the reference: {:.2}%",
                    e * 100.0
                ));
            }
            Some(Heat::NoReference) => {
                ui.label("no cached image reference for this view and frame");
            }
            None => {}
        }
        ui.separator();

        ui.label("time per frame, median (range) of the last frames, ms:");
        egui::Grid::new("times").striped(true).show(ui, |ui| {
            for s in state.clock.summaries() {
                ui.label(&s.name);
                ui.label(format!("{:.2}", s.median_ms));
                ui.label(format!("({:.2}–{:.2})", s.min_ms, s.max_ms));
                ui.end_row();
            }
        });
        let profile = state.profile();
        if !profile.is_empty() {
            ui.collapsing("the method's own profile of its last stages", |ui| {
                egui::ScrollArea::vertical()
                    .max_height(180.0)
                    .show(ui, |ui| {
                        egui::Grid::new("profile").striped(true).show(ui, |ui| {
                            for (stage, name, value) in profile {
                                if stage == Stage::Prepare {
                                    continue;
                                }
                                ui.label(stage.to_string());
                                ui.label(name);
                                ui.label(match value {
                                    ProfileValue::Seconds(s) => format!("{:.2} ms", s * 1e3),
                                    ProfileValue::Count(n) => n.to_string(),
                                });
                                ui.end_row();
                            }
                        });
                    });
            });
        }
    }

    /// Switches to the typed method; on an error the field shows the
    /// method that stays.
    fn apply(&mut self, state: &mut ViewState) {
        if let Err(e) = state.switch_method(self.name.trim()) {
            eprintln!("error: {e}");
            state.error = Some(e.to_string());
        }
        self.name = state.method_name().to_string();
    }
}
