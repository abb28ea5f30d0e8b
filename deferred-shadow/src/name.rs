//! The method's settings as a name a user types and a report prints:
//! `deferred-shadow`, then each setting that differs from
//! [`Config::default`], e.g. `deferred-shadow:q=64:map=128`.
//! [`Config::name`] writes the words [`Config::from_name`] reads, and
//! reading a written name gives the same settings back.

use shadow_core::{
    Result,
    name::{MethodName, NameWriter, Opt},
    sh::Window,
};

use crate::{Config, Grouping};

/// The family's name.
pub(crate) const NAME: &str = "deferred-shadow";

/// Every option, as `harness list` and typo messages show them.
pub const OPTIONS: &[&str] = &[
    "q=N",
    "map=N",
    "rays=N",
    "overlap=F",
    "groups=0+1,2",
    "uncorrected",
    "window=none|hanning|lanczos",
    "blocks",
];

impl Config {
    /// The settings `name` gives: `deferred-shadow`, then options after
    /// `:` in any order, on [`Config::default`]: `q=N` area lights, `map=N`
    /// occlusion map side, `rays=N` precomputation rays per vertex,
    /// `overlap=F` (objects whose boxes overlap by more than F form a group)
    /// or `groups=0+1,2` (object indices, `+` within a group, `,` between
    /// groups), `uncorrected` (eq. 4 instead of eq. 8),
    /// `window=none|hanning|lanczos`, `blocks` (L_o shared by 2×2 blocks
    /// of pixels, [`Config::blocks`]).
    ///
    /// Fails with [`shadow_core::Error::InvalidConfig`] naming the option
    /// (and the closest valid one for a typo) or the setting out of range.
    pub fn from_name(text: &str) -> Result<Config> {
        let name = MethodName::parse(text, NAME)?;
        let mut config = Config::default();
        for option in name.options() {
            read(&name, option, &mut config)?;
        }
        name.checked(config.check())?;
        Ok(config)
    }

    /// The name [`Config::from_name`] reads back to these settings.
    pub fn name(&self) -> String {
        let default = Config::default();
        let mut name = NameWriter::new(NAME);
        name.changed("q", self.lights, default.lights)
            .changed("map", self.map_resolution, default.map_resolution)
            .changed("rays", self.rays, default.rays);
        if self.grouping != default.grouping {
            match &self.grouping {
                Grouping::Overlapping { overlap } => name.value("overlap", overlap),
                Grouping::Explicit(groups) => name.value("groups", groups_name(groups)),
            };
        }
        name.switch("uncorrected", !self.self_visibility)
            .changed("window", self.window.name(), default.window.name())
            .switch("blocks", self.blocks);
        name.finish()
    }
}

/// Applies `option` of `name` to `config`.
fn read(name: &MethodName, option: Opt, config: &mut Config) -> Result<()> {
    match (option.key, option.value) {
        ("q", Some(q)) => config.lights = name.value(option, q)?,
        ("map", Some(n)) => config.map_resolution = name.value(option, n)?,
        ("rays", Some(n)) => config.rays = name.value(option, n)?,
        ("overlap", Some(f)) => {
            config.grouping = Grouping::Overlapping {
                overlap: name.value(option, f)?,
            }
        }
        ("groups", Some(groups)) => {
            config.grouping = Grouping::Explicit(
                groups
                    .split(',')
                    .map(|group| {
                        group
                            .split('+')
                            .map(|index| name.value(option, index))
                            .collect()
                    })
                    .collect::<Result<_>>()?,
            )
        }
        ("uncorrected", None) => config.self_visibility = false,
        ("blocks", None) => config.blocks = true,
        ("window", Some(w)) => {
            config.window = Window::from_name(w).ok_or_else(|| {
                name.error(format!("{option}: windows are none, hanning, lanczos"))
            })?
        }
        _ => return Err(name.unknown(option, OPTIONS)),
    }
    Ok(())
}

fn groups_name(groups: &[Vec<usize>]) -> String {
    groups
        .iter()
        .map(|group| {
            group
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join("+")
        })
        .collect::<Vec<_>>()
        .join(",")
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    #[test]
    fn names_say_what_differs_from_the_default() {
        assert_eq!(Config::default().name(), "deferred-shadow");
        let config = Config {
            lights: 64,
            grouping: Grouping::Explicit(vec![vec![0, 2], vec![1]]),
            self_visibility: false,
            blocks: true,
            ..Config::default()
        };
        assert_eq!(
            config.name(),
            "deferred-shadow:q=64:groups=0+2,1:uncorrected:blocks"
        );
    }

    #[test]
    fn bad_names_say_what_is_wrong() {
        for (text, says) in [
            ("deferred-shadow:q=0", "area lights"),
            ("deferred-shadow:map=x", "whole number"),
            ("deferred-shadow:groups=0+x", "whole number"),
            ("deferred-shadow:overlap=2", "overlap"),
            ("deferred-shadow:window=box", "windows are"),
            ("deferred-shadow:rasy=64", "did you mean rays=N?"),
        ] {
            let err = Config::from_name(text).unwrap_err().to_string();
            assert!(err.contains(says) && err.contains(text), "{text}: {err}");
        }
    }

    fn config() -> impl Strategy<Value = Config> {
        let grouping = prop_oneof![
            (0.01_f32..=1.0).prop_map(|overlap| Grouping::Overlapping { overlap }),
            prop::collection::vec(prop::collection::vec(0_usize..9, 1..3), 1..4)
                .prop_map(Grouping::Explicit),
        ];
        (
            1_usize..=crate::MAX_LIGHTS,
            4_u32..=crate::MAX_MAP_RESOLUTION,
            16_u32..=65536,
            grouping,
            any::<bool>(),
            prop::sample::select(vec![Window::None, Window::Hanning, Window::Lanczos]),
            any::<bool>(),
        )
            .prop_map(
                |(lights, map_resolution, rays, grouping, self_visibility, window, blocks)| {
                    Config {
                        lights,
                        map_resolution,
                        rays,
                        grouping,
                        self_visibility,
                        window,
                        blocks,
                    }
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
