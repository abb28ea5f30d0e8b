//! The method's settings as a name a user types and a report prints:
//! `occlusion-query`, then each setting that differs from the preset it
//! starts from, e.g. `occlusion-query:k=66:queries:filter` or
//! `occlusion-query:paper:k=66`. [`Config::name`] writes the words
//! [`Config::from_name`] reads, and reading a written name gives the same
//! settings back.

use shadow_core::{
    Result,
    name::{MethodName, NameWriter, Opt},
};

use crate::{
    Config, DepthOffset, Filtering, Level, Normalization, Occluder, Orientation, VertexTest,
    Weights,
};

/// The family's name.
pub(crate) const NAME: &str = "occlusion-query";

/// Every option, as `harness list` and typo messages show them.
pub const OPTIONS: &[&str] = &[
    "paper",
    "k=N",
    "queries",
    "test=queries|compare",
    "weights=voronoi|equal",
    "raw",
    "normalize=off|vertex",
    "axes",
    "orientation=axes|turned",
    "idle=K",
    "filter",
    "filter=FRACTION",
    "simplified",
    "simplified=TEXELS",
    "map=N",
    "offset=default|paper|none|TERMS",
    "blur=F",
];

impl Config {
    /// The settings `name` gives: `occlusion-query`, then options after `:`
    /// in any order. The preset `paper` ([`Config::paper`]) is the base the
    /// others change wherever it stands, else [`Config::default`]:
    ///
    /// * `k=N`: lightsphere directions (6, 18, 66, 258, 1026, 4098);
    /// * `queries` (`test=queries|compare`): the vertex test;
    /// * `weights=voronoi|equal`; `raw` (`normalize=off|vertex`);
    /// * `axes` (`orientation=axes|turned`): the lightsphere's orientation;
    /// * `idle=K`: refine up to K directions while the geometry stays;
    /// * `filter` (`filter=FRACTION`): vertex filtering from the camera;
    /// * `simplified` (`simplified=TEXELS`): simplified occluders
    ///   ([`Config::fast`]'s half texel by default);
    /// * `map=N`: depth map side;
    /// * `offset=default|paper|none` or its non-zero terms joined by `,`
    ///   (`f` occluder slope, `u` units, `c` clamp, `s` receiver slope, `l`
    ///   toward the light, `n` along the normal: `offset=f1,u1`);
    /// * `blur=F`: the environment's prefilter width in lightsphere spacings.
    ///
    /// Fails with [`shadow_core::Error::InvalidConfig`] naming the option
    /// (and the closest valid one for a typo) or the setting out of range.
    pub fn from_name(text: &str) -> Result<Config> {
        let name = MethodName::parse(text, NAME)?;
        let mut config = if name.has("paper") {
            Config::paper()
        } else {
            Config::default()
        };
        for option in name.options() {
            read(&name, option, &mut config)?;
        }
        name.checked(config.check())?;
        Ok(config)
    }

    /// The name [`Config::from_name`] reads back to these settings: the
    /// preset they start from (`paper` where test, weights, normalization,
    /// orientation and offset are the paper's) and each setting that
    /// differs from it.
    pub fn name(&self) -> String {
        let paper = Config::paper();
        let from_paper = self.test == paper.test
            && self.weights == paper.weights
            && self.normalization == paper.normalization
            && self.orientation == paper.orientation
            && self.offset == paper.offset;
        let base = if from_paper { paper } else { Config::default() };
        let mut name = NameWriter::new(NAME);
        name.switch("paper", from_paper).changed(
            "k",
            self.level.directions(),
            base.level.directions(),
        );
        if self.test != base.test {
            match self.test {
                VertexTest::OcclusionQuery => name.switch("queries", true),
                VertexTest::DepthCompare => name.value("test", "compare"),
            };
        }
        if self.weights != base.weights {
            name.value("weights", weights_name(self.weights));
        }
        if self.normalization != base.normalization {
            match self.normalization {
                Normalization::Off => name.switch("raw", true),
                Normalization::PerVertex => name.value("normalize", "vertex"),
            };
        }
        if self.orientation != base.orientation {
            match self.orientation {
                Orientation::Axes => name.switch("axes", true),
                Orientation::Turned => name.value("orientation", "turned"),
            };
        }
        if let Some(idle) = self.idle_level {
            name.value("idle", idle.directions());
        }
        match self.filtering {
            Some(f) if f == Filtering::default() => name.switch("filter", true),
            Some(f) => name.value("filter", f.threshold),
            None => &mut name,
        };
        match self.occluder {
            Occluder::Full => &mut name,
            o if o == Config::fast().occluder => name.switch("simplified", true),
            Occluder::Simplified { texels } => name.value("simplified", texels),
        };
        name.changed("map", self.map_resolution, base.map_resolution);
        if self.offset != base.offset {
            name.value("offset", offset_name(self.offset));
        }
        name.changed("blur", self.prefilter, base.prefilter);
        name.finish()
    }
}

/// Applies `option` of `name` to `config`.
fn read(name: &MethodName, option: Opt, config: &mut Config) -> Result<()> {
    let bad = |what: String| Err(name.error(format!("{option}: {what}")));
    match (option.key, option.value) {
        ("paper", None) => {}
        ("k", Some(k)) => {
            config.level = match Level::with_directions(name.value(option, k)?) {
                Some(level) => level,
                None => {
                    return bad(
                        "the lightsphere has 6, 18, 66, 258, 1026 or 4098 directions".into(),
                    );
                }
            }
        }
        ("idle", Some(k)) => {
            config.idle_level = match Level::with_directions(name.value(option, k)?) {
                Some(level) => Some(level),
                None => {
                    return bad(
                        "the lightsphere has 6, 18, 66, 258, 1026 or 4098 directions".into(),
                    );
                }
            }
        }
        ("queries", None) => config.test = VertexTest::OcclusionQuery,
        ("test", Some("queries")) => config.test = VertexTest::OcclusionQuery,
        ("test", Some("compare")) => config.test = VertexTest::DepthCompare,
        ("weights", Some(w)) => {
            config.weights = match w {
                "voronoi" => Weights::Voronoi,
                "equal" => Weights::Equal,
                _ => return bad("weights are voronoi or equal".into()),
            }
        }
        ("raw", None) | ("normalize", Some("off")) => config.normalization = Normalization::Off,
        ("normalize", Some("vertex")) => config.normalization = Normalization::PerVertex,
        ("axes", None) | ("orientation", Some("axes")) => config.orientation = Orientation::Axes,
        ("orientation", Some("turned")) => config.orientation = Orientation::Turned,
        ("filter", None) => config.filtering = Some(Filtering::default()),
        ("filter", Some(t)) => {
            config.filtering = Some(Filtering {
                threshold: name.value(option, t)?,
            })
        }
        ("simplified", None) => config.occluder = Config::fast().occluder,
        ("simplified", Some(t)) => {
            config.occluder = Occluder::Simplified {
                texels: name.value(option, t)?,
            }
        }
        ("map", Some(n)) => config.map_resolution = name.value(option, n)?,
        ("offset", Some(terms)) => config.offset = offset(name, option, terms)?,
        ("blur", Some(b)) => config.prefilter = name.value(option, b)?,
        _ => return Err(name.unknown(option, OPTIONS)),
    }
    Ok(())
}

fn weights_name(weights: Weights) -> &'static str {
    match weights {
        Weights::Voronoi => "voronoi",
        Weights::Equal => "equal",
    }
}

/// The letters of [`DepthOffset`]'s terms in `offset=`, in order.
const TERMS: [char; 6] = ['f', 'u', 'c', 's', 'l', 'n'];

fn terms(offset: DepthOffset) -> [f32; 6] {
    [
        offset.occluder_slope,
        offset.occluder_units as f32,
        offset.occluder_clamp,
        offset.receiver_slope,
        offset.toward_light,
        offset.along_normal,
    ]
}

/// `offset=`'s value for `offset`: a preset's name, else its non-zero
/// terms (`f1,u1`).
fn offset_name(offset: DepthOffset) -> String {
    match offset {
        DepthOffset::DEFAULT => "default".into(),
        DepthOffset::PAPER => "paper".into(),
        DepthOffset::NONE => "none".into(),
        _ => TERMS
            .iter()
            .zip(terms(offset))
            .filter(|(_, value)| *value != 0.0)
            .map(|(letter, value)| format!("{letter}{value}"))
            .collect::<Vec<_>>()
            .join(","),
    }
}

/// The offset `offset=text` gives.
fn offset(name: &MethodName, option: Opt, text: &str) -> Result<DepthOffset> {
    match text {
        "default" => return Ok(DepthOffset::DEFAULT),
        "paper" => return Ok(DepthOffset::PAPER),
        "none" => return Ok(DepthOffset::NONE),
        _ => {}
    }
    let mut values = [0.0_f32; 6];
    for term in text.split(',') {
        let mut letters = term.chars();
        let slot = letters
            .next()
            .and_then(|letter| TERMS.iter().position(|t| *t == letter));
        match slot {
            Some(slot) => values[slot] = name.value(option, letters.as_str())?,
            None => {
                return Err(name.error(format!(
                    "{option}: terms are f, u, c, s, l and n followed by a number (offset=f1,u1), or default, paper, none"
                )));
            }
        }
    }
    let [
        occluder_slope,
        units,
        occluder_clamp,
        receiver_slope,
        toward_light,
        along_normal,
    ] = values;
    if units.fract() != 0.0 || units < 0.0 {
        return Err(name.error(format!("{option}: u (units) is a whole number")));
    }
    Ok(DepthOffset {
        occluder_slope,
        occluder_units: units as u32,
        occluder_clamp,
        receiver_slope,
        toward_light,
        along_normal,
    })
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    #[test]
    fn presets_have_short_names() {
        assert_eq!(Config::default().name(), "occlusion-query");
        assert_eq!(Config::fast().name(), "occlusion-query:simplified");
        assert_eq!(Config::paper().name(), "occlusion-query:paper");
        let paper_66 = Config {
            level: Level::with_directions(66).unwrap(),
            ..Config::paper()
        };
        assert_eq!(paper_66.name(), "occlusion-query:paper:k=66");
        // The preset is the base wherever it stands.
        for text in ["occlusion-query:k=66:paper", "occlusion-query:paper:k=66"] {
            assert_eq!(Config::from_name(text).unwrap(), paper_66, "{text}");
        }
    }

    #[test]
    fn every_setting_shows_in_the_name() {
        let changed = Config {
            idle_level: Level::new(4),
            filtering: Some(Filtering { threshold: 0.1 }),
            occluder: Occluder::Simplified { texels: 2.0 },
            map_resolution: 256,
            offset: DepthOffset {
                along_normal: 0.75,
                ..DepthOffset::NONE
            },
            prefilter: 0.3,
            ..Config::default()
        };
        assert_eq!(
            changed.name(),
            "occlusion-query:idle=1026:filter=0.1:simplified=2:map=256:offset=n0.75:blur=0.3"
        );
        let compare = Config {
            test: VertexTest::DepthCompare,
            ..Config::paper()
        };
        assert_eq!(
            compare.name(),
            "occlusion-query:weights=equal:raw:axes:offset=paper"
        );
    }

    #[test]
    fn bad_names_say_what_is_wrong() {
        for (text, says) in [
            ("occlusion-query:k=100", "4098 directions"),
            ("occlusion-query:map=x", "whole number"),
            ("occlusion-query:map=2", "depth map resolution"),
            ("occlusion-query:blur=-1", "prefilter"),
            ("occlusion-query:querys", "did you mean queries?"),
            ("occlusion-query:offset=q1", "terms are"),
            ("occlusion-query:offset=u0.5", "whole number"),
            ("occlusion-queryx", "options follow"),
        ] {
            let err = Config::from_name(text).unwrap_err().to_string();
            assert!(err.contains(says) && err.contains(text), "{text}: {err}");
        }
    }

    fn level() -> impl Strategy<Value = Level> {
        prop::sample::select(vec![6_usize, 18, 66, 258, 1026, 4098])
            .prop_map(|k| Level::with_directions(k).unwrap())
    }

    fn offset() -> impl Strategy<Value = DepthOffset> {
        let term = prop::sample::select(vec![0.0_f32, 0.5, 1.0, 2.25]);
        let presets = prop::sample::select(vec![
            DepthOffset::DEFAULT,
            DepthOffset::PAPER,
            DepthOffset::NONE,
        ]);
        let any = (
            term.clone(),
            0_u32..3,
            term.clone(),
            term.clone(),
            term.clone(),
            term,
        )
            .prop_map(|(f, u, c, s, l, n)| DepthOffset {
                occluder_slope: f,
                occluder_units: u,
                occluder_clamp: c,
                receiver_slope: s,
                toward_light: l,
                along_normal: n,
            });
        prop_oneof![presets, any]
    }

    fn config() -> impl Strategy<Value = Config> {
        (
            (level(), any::<bool>(), prop::option::of(level())),
            (any::<bool>(), any::<bool>(), any::<bool>()),
            prop::option::of(0.0_f32..=1.0),
            prop::option::of(0.1_f32..8.0),
            (8_u32..=4096, offset(), 0.0_f32..2.0),
        )
            .prop_map(
                |(
                    (level, axes, idle_level),
                    (equal, raw, queries),
                    filter,
                    simplified,
                    (map_resolution, offset, prefilter),
                )| Config {
                    level,
                    orientation: if axes {
                        Orientation::Axes
                    } else {
                        Orientation::Turned
                    },
                    idle_level,
                    weights: if equal {
                        Weights::Equal
                    } else {
                        Weights::Voronoi
                    },
                    normalization: if raw {
                        Normalization::Off
                    } else {
                        Normalization::PerVertex
                    },
                    test: if queries {
                        VertexTest::OcclusionQuery
                    } else {
                        VertexTest::DepthCompare
                    },
                    map_resolution,
                    offset,
                    filtering: filter.map(|threshold| Filtering { threshold }),
                    occluder: simplified
                        .map_or(Occluder::Full, |texels| Occluder::Simplified { texels }),
                    prefilter,
                },
            )
    }

    proptest! {
        /// A written name reads back to the same settings.
        #[test]
        fn names_read_back_to_their_settings(config in config()) {
            let name = config.name();
            prop_assert_eq!(Config::from_name(&name).unwrap(), config, "{}", name);
        }
    }
}
