//! The report's pictures ([`crate::pictures`]): the strip, where per-pixel
//! and per-vertex methods draw the bunny's contact shadow side by side, and
//! in the atlas each failing setting beside its remedy. A row per setting:
//! its picture, then its error map at the same size.

use super::{AtlasRun, Block, Document, Figure, Report};
use crate::{
    pictures::{Picture, Pictures},
    suite::{STRIP_SCENE, Suite},
};

impl Report {
    /// The pictures taken of `scene`, if any.
    pub fn pictures_of(&self, scene: &str) -> Option<&Pictures> {
        self.pictures.iter().find(|p| p.scene == scene)
    }

    /// The strip's section: the reference, then each strip setting's
    /// picture beside its error map.
    pub(super) fn strip_blocks(&self, doc: &mut Document) {
        let Some(set) = self.pictures_of(STRIP_SCENE) else {
            return;
        };
        let settings: Vec<String> = Suite::strip_settings()
            .iter()
            .map(|m| m.name().to_string())
            .collect();
        let rows = rows(set, settings.iter().map(String::as_str));
        if rows.is_empty() {
            return;
        }
        doc.push(Block::Heading(
            2,
            format!("Per pixel against per vertex: {STRIP_SCENE}"),
        ));
        doc.push(Block::Paragraph(format!(
            "The contact shadow on a floor of two triangles: per-vertex methods interpolate \
             between the floor's four corners, deferred shadowing draws it per pixel. {} Each row: \
             a setting's picture (the reference's exposure) and its relative error per pixel \
             (0.1% to 100%, logarithmic, the colour scale beneath each map).",
            framing(set)
        )));
        doc.push(reference_row(set));
        for block in rows {
            doc.push(block);
        }
    }
}

/// The atlas's pictures of `scene`: after the reference, each failing
/// setting of `runs` (in their order) and the remedy that follows it; none
/// without pictures of the scene.
pub(super) fn atlas_rows(report: &Report, scene: &str, runs: &[&AtlasRun]) -> Vec<Block> {
    let Some(set) = report.pictures_of(scene) else {
        return Vec::new();
    };
    let shown = runs
        .iter()
        .filter(|r| r.remedy_for.is_some() || r.fails(&report.runs))
        .map(|r| r.setting.as_str());
    let rows = rows(set, shown);
    if rows.is_empty() {
        return Vec::new();
    }
    let mut blocks = vec![
        Block::Paragraph(format!(
            "{} Each row: a failing setting or its remedy, and its error map.",
            framing(set)
        )),
        reference_row(set),
    ];
    blocks.extend(rows);
    blocks
}

/// A row per setting of `settings` that `set` pictured, or a sentence
/// where its picture failed; nothing for the others.
fn rows<'a>(set: &Pictures, settings: impl Iterator<Item = &'a str>) -> Vec<Block> {
    settings
        .filter_map(|setting| match set.of(setting) {
            Some(picture) => Some(row(set, picture)),
            None => set
                .failed
                .iter()
                .find(|f| f.setting == setting)
                .map(|f| Block::Paragraph(format!("No picture of {setting}: {}.", f.why))),
        })
        .collect()
}

/// What the pictures show: the frame, the zoom, the reference's noise.
fn framing(set: &Pictures) -> String {
    let zoom = if set.zoom < 1.0 {
        format!(
            "zoomed {:.1}× onto where the shown settings' errors concentrate in the scored images",
            1.0 / set.zoom
        )
    } else {
        "the whole view (the errors spread over it)".to_string()
    };
    format!(
        "Pictures {}×{} of frame {}, {zoom}; their reference's noise is {:.1}%.",
        set.width,
        set.height,
        set.frame,
        set.reference_noise * 100.0
    )
}

fn reference_row(set: &Pictures) -> Block {
    Block::Figures(vec![Figure {
        path: format!("{}/reference.png", set.folder),
        caption: "reference".into(),
    }])
}

/// A setting's picture and its error map, side by side.
fn row(set: &Pictures, picture: &Picture) -> Block {
    Block::Figures(vec![
        Figure {
            path: format!("{}/{}.png", set.folder, picture.stem),
            caption: format!(
                "{}: {:.1}% error in this view",
                picture.setting,
                picture.error * 100.0
            ),
        },
        Figure {
            path: format!("{}/{}-error.png", set.folder, picture.stem),
            caption: format!("{} error", picture.setting),
        },
    ])
}
