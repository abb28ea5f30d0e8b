//! The method's settings as a name a user types and a report prints:
//! `hemi-raster`, then each setting that differs from the preset it starts
//! from, e.g. `hemi-raster:pvs:mask=16`. [`Config::name`] writes the words
//! [`Config::from_name`] reads, and reading a written name gives the same
//! settings back.

use std::num::NonZeroU32;

use shadow_core::{
    Result,
    name::{MethodName, NameWriter, Opt},
    sh::{ShOrder, Window},
};

use crate::{
    BackfaceCulling, Config, Hierarchy, Integration, MaskResolution, NearRings, Pvs, Simd,
};

/// The family's name.
pub(crate) const NAME: &str = "hemi-raster";

/// Every option, as `harness list` and typo messages show them.
pub const OPTIONS: &[&str] = &[
    "flat",
    "pvs",
    "pvs=N",
    "mask=16|32|64",
    "table=N",
    "order=N",
    "paper",
    "blocks",
    "direct",
    "window=none|hanning|lanczos",
    "reach=N",
    "min=N",
    "coarse=N",
    "rings=1|2",
    "chords=replace|keep",
    "cull=auto|on|off",
    "simd=auto|portable|avx2|avx512",
];

impl Config {
    /// The settings `name` gives: `hemi-raster`, then options after `:` in
    /// any order, on [`Config::default`]:
    ///
    /// * `flat`: no hierarchy ([`Config::accurate`]);
    /// * `pvs` (`pvs=N`: from every Nth frame): visible sets from the
    ///   scene's own frames, with [`Config::fast`]'s wide near reach unless
    ///   `reach=` says otherwise;
    /// * `mask=16|32|64`, `table=N` (plane-table cells per cube-face side),
    ///   `order=N` (SH order), `window=none|hanning|lanczos`;
    /// * `paper`: [`Config::paper`] as the base the other options change;
    /// * `blocks` (SH from 4×4 blocks), `direct` (no SH);
    /// * the hierarchy's `reach=N` (near reach in coarse-triangle radii),
    ///   `min=N` (least coarse triangle count), `coarse=N` (the
    ///   simplification's divisor), `rings=1|2`, `chords=replace|keep`
    ///   (coarse triangles too close to a receiver replaced by their fine
    ///   ones, or kept however close);
    /// * `cull=auto|on|off` (back faces), `simd=auto|portable|avx2|avx512`.
    ///
    /// Fails with [`shadow_core::Error::InvalidConfig`] naming the option
    /// (and the closest valid one for a typo) or the setting out of range.
    pub fn from_name(text: &str) -> Result<Config> {
        let name = MethodName::parse(text, NAME)?;
        let paper = name.options().any(|o| (o.key, o.value) == ("paper", None));
        let mut config = if paper {
            Config::paper()
        } else {
            Config::default()
        };
        // The switches that choose a base go first, so that the options
        // compose in any order.
        for option in name.options() {
            match (option.key, option.value) {
                ("flat", None) => config.hierarchy = Hierarchy::Flat,
                ("pvs", None) => config.pvs = Pvs::EVERY_FRAME,
                ("pvs", Some(n)) => {
                    let stride = NonZeroU32::new(name.value(option, n)?)
                        .ok_or_else(|| name.error("pvs=0: the stride is at least 1"))?;
                    config.pvs = Pvs::Animation { stride };
                }
                _ => {}
            }
        }
        if config.pvs != Pvs::Off && !paper {
            config.hierarchy = config.hierarchy.with_near_reach(Hierarchy::WIDE_NEAR_REACH);
        }
        for option in name.options() {
            read(&name, option, &mut config)?;
        }
        name.checked(config.validate())?;
        Ok(config)
    }

    /// The name [`Config::from_name`] reads back to these settings: the
    /// shorter of the names on [`Config::default`] and, where the
    /// integration is the paper's, on [`Config::paper`].
    pub fn name(&self) -> String {
        let plain = self.name_on(false);
        if self.integration != Integration::ShBlocks {
            return plain;
        }
        let paper = self.name_on(true);
        if paper.len() < plain.len() {
            paper
        } else {
            plain
        }
    }

    /// The name of these settings as changes to [`Config::paper`]
    /// (`paper`, whose integration must be this one's) or to
    /// [`Config::default`].
    fn name_on(&self, paper: bool) -> String {
        let mut name = NameWriter::new(NAME);
        name.switch("paper", paper);
        name.switch("flat", self.hierarchy == Hierarchy::Flat);
        match self.pvs {
            Pvs::Off => {}
            Pvs::Animation { stride } if stride.get() == 1 => {
                name.switch("pvs", true);
            }
            Pvs::Animation { stride } => {
                name.value("pvs", stride);
            }
        }
        let default = if paper {
            Config::paper()
        } else {
            Config::default()
        };
        name.changed(
            "mask",
            self.mask_resolution.pixels_per_side(),
            default.mask_resolution.pixels_per_side(),
        )
        .changed("table", self.lut_resolution, default.lut_resolution)
        .changed("order", self.order.get(), default.order.get())
        .switch(
            "blocks",
            !paper && self.integration == Integration::ShBlocks,
        )
        .switch("direct", self.integration == Integration::Direct)
        .changed("window", self.window.name(), default.window.name());
        let base = match self.pvs {
            Pvs::Animation { .. } if !paper => Config::fast().hierarchy,
            _ => default.hierarchy,
        };
        if let (
            Hierarchy::TwoLevel {
                coarse_divisor,
                min_coarse_triangles,
                near,
                near_reach,
                replace_near_chords,
            },
            Hierarchy::TwoLevel {
                coarse_divisor: d,
                min_coarse_triangles: m,
                near: n,
                near_reach: r,
                replace_near_chords: c,
            },
        ) = (self.hierarchy, base)
        {
            name.changed("reach", near_reach, r)
                .changed("min", min_coarse_triangles, m)
                .changed("coarse", coarse_divisor, d)
                .changed("rings", rings(near), rings(n))
                .changed("chords", chords(replace_near_chords), chords(c));
        }
        name.changed(
            "cull",
            culling_name(self.backface_culling),
            culling_name(default.backface_culling),
        )
        .changed("simd", simd_name(self.simd), simd_name(default.simd));
        name.finish()
    }
}

/// Applies `option` of `name` to `config` (the base switches are already
/// applied).
fn read(name: &MethodName, option: Opt, config: &mut Config) -> Result<()> {
    let bad = |what: &str| Err(name.error(format!("{option}: {what}")));
    match (option.key, option.value) {
        ("flat" | "pvs" | "paper", _) => {}
        ("mask", Some(n)) => {
            config.mask_resolution = match name.value(option, n)? {
                16 => MaskResolution::R16,
                32 => MaskResolution::R32,
                64 => MaskResolution::R64,
                _ => return bad("masks are 16, 32 or 64 pixels a side"),
            }
        }
        ("table", Some(n)) => config.lut_resolution = name.value(option, n)?,
        ("order", Some(n)) => match ShOrder::new(name.value(option, n)?) {
            Some(order) => config.order = order,
            None => {
                return Err(name.error(format!(
                    "{option}: SH orders are 1 to {}",
                    ShOrder::MAX.get()
                )));
            }
        },
        ("blocks", None) => config.integration = Integration::ShBlocks,
        ("direct", None) => config.integration = Integration::Direct,
        ("window", Some(w)) => match Window::from_name(w) {
            Some(window) => config.window = window,
            None => return bad("windows are none, hanning, lanczos"),
        },
        ("reach", Some(n)) => *two_level(name, option, config)?.3 = name.value(option, n)?,
        ("min", Some(n)) => *two_level(name, option, config)?.1 = name.value(option, n)?,
        ("coarse", Some(n)) => *two_level(name, option, config)?.0 = name.value(option, n)?,
        ("rings", Some(n)) => {
            *two_level(name, option, config)?.2 = match n {
                "1" => NearRings::One,
                "2" => NearRings::Two,
                _ => return bad("the near field is 1 or 2 rings"),
            }
        }
        ("chords", Some(c)) => {
            *two_level(name, option, config)?.4 = match c {
                "replace" => true,
                "keep" => false,
                _ => return bad("near chords are replaced or kept"),
            }
        }
        ("cull", Some(c)) => {
            config.backface_culling = match c {
                "auto" => BackfaceCulling::Auto,
                "on" => BackfaceCulling::On,
                "off" => BackfaceCulling::Off,
                _ => return bad("culling is auto, on or off"),
            }
        }
        ("simd", Some(s)) => {
            config.simd = match s {
                "auto" => Simd::Auto,
                "portable" => Simd::Portable,
                "avx2" => Simd::Avx2,
                "avx512" => Simd::Avx512,
                _ => return bad("paths are auto, portable, avx2, avx512"),
            }
        }
        _ => return Err(name.unknown(option, OPTIONS)),
    }
    Ok(())
}

/// The two-level hierarchy's settings, which `option` changes.
type TwoLevel<'c> = (
    &'c mut NonZeroU32,
    &'c mut u32,
    &'c mut NearRings,
    &'c mut u8,
    &'c mut bool,
);

fn two_level<'c>(name: &MethodName, option: Opt, config: &'c mut Config) -> Result<TwoLevel<'c>> {
    match &mut config.hierarchy {
        Hierarchy::TwoLevel {
            coarse_divisor,
            min_coarse_triangles,
            near,
            near_reach,
            replace_near_chords,
        } => Ok((
            coarse_divisor,
            min_coarse_triangles,
            near,
            near_reach,
            replace_near_chords,
        )),
        Hierarchy::Flat => Err(name.error(format!(
            "{option}: a setting of the hierarchy, which flat turns off"
        ))),
    }
}

fn chords(replace: bool) -> &'static str {
    if replace { "replace" } else { "keep" }
}

fn rings(near: NearRings) -> u8 {
    match near {
        NearRings::One => 1,
        NearRings::Two => 2,
    }
}

fn culling_name(culling: BackfaceCulling) -> &'static str {
    match culling {
        BackfaceCulling::Auto => "auto",
        BackfaceCulling::On => "on",
        BackfaceCulling::Off => "off",
    }
}

fn simd_name(simd: Simd) -> &'static str {
    match simd {
        Simd::Auto => "auto",
        Simd::Portable => "portable",
        Simd::Avx2 => "avx2",
        Simd::Avx512 => "avx512",
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    #[test]
    fn presets_have_short_names() {
        assert_eq!(Config::default().name(), "hemi-raster");
        assert_eq!(Config::fast().name(), "hemi-raster:pvs");
        assert_eq!(Config::accurate().name(), "hemi-raster:flat");
        assert_eq!(Config::paper().name(), "hemi-raster:paper");
        for (text, preset) in [
            ("hemi-raster", Config::default()),
            ("hemi-raster:pvs", Config::fast()),
            ("hemi-raster:flat", Config::accurate()),
            ("hemi-raster:paper", Config::paper()),
        ] {
            assert_eq!(Config::from_name(text).unwrap(), preset, "{text}");
        }
    }

    /// `pvs` widens the near reach unless `reach=` is given, wherever it
    /// stands.
    #[test]
    fn options_compose_in_any_order() {
        let a = Config::from_name("hemi-raster:pvs:reach=2").unwrap();
        let b = Config::from_name("hemi-raster:reach=2:pvs").unwrap();
        assert_eq!(a, b);
        assert_eq!(a.hierarchy, Hierarchy::default());
        assert_eq!(a.name(), "hemi-raster:pvs:reach=2");
        let half = Config::from_name("hemi-raster:min=40:pvs=2").unwrap();
        assert_eq!(
            half.hierarchy,
            Hierarchy::default()
                .with_min_coarse_triangles(40)
                .with_near_reach(Hierarchy::WIDE_NEAR_REACH)
        );
        assert_eq!(half.name(), "hemi-raster:pvs=2:min=40");
    }

    #[test]
    fn bad_names_say_what_is_wrong() {
        for (text, says) in [
            ("hemi-raster:mask=24", "16, 32 or 64"),
            ("hemi-raster:table=63", "plane LUT resolution 63"),
            ("hemi-raster:order=0", "SH orders"),
            ("hemi-raster:reach=300", "whole number"),
            ("hemi-raster:flat:reach=3", "flat turns off"),
            ("hemi-raster:pvs=0", "at least 1"),
            ("hemi-raster:fast", "options are"),
            ("hemi-raster:mask", "did you mean mask=16|32|64?"),
            ("hemi-rasterx", "options follow"),
        ] {
            let err = Config::from_name(text).unwrap_err().to_string();
            assert!(err.contains(says) && err.contains(text), "{text}: {err}");
        }
    }

    fn config() -> impl Strategy<Value = Config> {
        let hierarchy = prop_oneof![
            Just(Hierarchy::Flat),
            (
                1_u32..20,
                0_u32..500,
                any::<bool>(),
                0_u8..10,
                any::<bool>()
            )
                .prop_map(|(d, m, one, r, replace)| Hierarchy::TwoLevel {
                    coarse_divisor: NonZeroU32::new(d).unwrap(),
                    min_coarse_triangles: m,
                    near: if one { NearRings::One } else { NearRings::Two },
                    near_reach: r,
                    replace_near_chords: replace,
                }),
        ];
        (
            prop::sample::select(vec![
                MaskResolution::R16,
                MaskResolution::R32,
                MaskResolution::R64,
            ]),
            prop::sample::select(vec![32_usize, 64, 128, 256]),
            1_u32..=ShOrder::MAX.get(),
            prop::sample::select(vec![Window::None, Window::Hanning, Window::Lanczos]),
            prop::sample::select(vec![
                Integration::ShPixels,
                Integration::ShBlocks,
                Integration::Direct,
            ]),
            prop::sample::select(vec![
                BackfaceCulling::Auto,
                BackfaceCulling::On,
                BackfaceCulling::Off,
            ]),
            hierarchy,
            prop::option::of(1_u32..4),
            prop::sample::select(vec![Simd::Auto, Simd::Portable, Simd::Avx2, Simd::Avx512]),
        )
            .prop_map(
                |(
                    mask_resolution,
                    lut_resolution,
                    order,
                    window,
                    integration,
                    culling,
                    hierarchy,
                    pvs,
                    simd,
                )| {
                    Config {
                        mask_resolution,
                        lut_resolution,
                        order: ShOrder::new(order).unwrap(),
                        window,
                        integration,
                        backface_culling: culling,
                        hierarchy,
                        pvs: pvs.map_or(Pvs::Off, |s| Pvs::Animation {
                            stride: NonZeroU32::new(s).unwrap(),
                        }),
                        simd,
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
