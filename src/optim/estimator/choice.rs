//! `method = "auto"`: the estimator chosen by the task's regime.
//!
//! ReSTIR reuses each texel's samples across iterations: it pays where a texel gets few
//! gradient samples per iteration. Its merge re-evaluates every kept path of every observed
//! texel, every iteration, a cost that grows with the observed texels and not with the
//! samples drawn: where the primal render is cheap it halves an iteration's rate, which a
//! small problem repays (its budget holds many iterations, and noise limits it) and a large
//! one does not. docs/studies.md, "The estimator by regime", measures the rule on the bench
//! scenes at scales 1, 2 and 4 in both sampling protocols. The rule reads the task's settings
//! and sizes only, so that a run's choice is known before any pass is compiled and is the
//! same on every machine.
use super::Method;

/// Gradient samples per texel per iteration from which `auto` takes the baseline: about
/// one sample per texel or more leaves reuse little to add (the default task: 2.0, where
/// the baseline ends lower; the bench scenes: 0.25, where ReSTIR ends level or lower).
pub const DENSE_SAMPLES_PER_TEXEL: f64 = 1.0;

/// Primal samples per gradient sample from which `auto` takes ReSTIR in the sparse regime
/// whatever the size: the primal then dominates an iteration and ReSTIR's merge adds little
/// to it (the geometric mean of the two sampling settings measured on the bench scenes, the
/// tasks' 2 : 1 and the paper's 32 : 1; 8 : 1 measured as well).
pub const RESTIR_PRIMAL_RATIO: f64 = 8.0;

/// Optimized texels from which `auto` takes the baseline in the sparse regime when the primal
/// is cheap: ReSTIR's merge over that many texels costs more than the primal render and
/// halves the iterations of a budget (measured: `lattice` at 1024² texels with a 2-spp primal
/// ends at 1.30x the baseline's texture error with two seeds, `vase` at 1024² level; every
/// scene at 512² and below level or lower).
pub const RESTIR_MAX_TEXELS_CHEAP_PRIMAL: u64 = 1 << 20;

/// The rule in one sentence, with its thresholds (for `psrestir estimators` and reports).
pub fn rule() -> String {
    format!(
        "the baseline where a normal map is optimized (ReSTIR's derivatives of one cost it 2.5x the \
         baseline's time per iteration on `wall`, where it ended at 1.41x the baseline's \
         base-color error at 60 s), where the environment is recovered (the light's fit is plain Monte Carlo \
         in every estimator and needs iterations) and with indirect light (max_depth above 1: \
         with whole paths reused, ReSTIR with its best step ended at 0.93x the baseline's \
         texture error on gallery and 1.09x on atelier, measured at 60 s on lavapipe: no gain \
         to count on); with direct light, the baseline where the gradient pass draws at least {DENSE_SAMPLES_PER_TEXEL} sample \
         per optimized texel and iteration; below that, ReSTIR where the primal takes at least \
         {RESTIR_PRIMAL_RATIO} samples per gradient sample or the textures have fewer than \
         {RESTIR_MAX_TEXELS_CHEAP_PRIMAL} texels, the baseline otherwise"
    )
}

/// What the rule reads: a task's sampling and sizes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Regime {
    /// Primal samples per pixel.
    pub primal_spp: u32,
    /// Gradient samples per pixel.
    pub gradient_spp: u32,
    /// Pixels rendered per iteration (all cameras).
    pub pixels: u64,
    /// Optimized texels (all textures).
    pub texels: u64,
    /// Vertices of a camera path (1: direct light only).
    pub max_depth: u32,
    /// Whether the environment is recovered with the textures.
    pub recovers_light: bool,
    /// Whether a normal map is optimized.
    pub normal_maps: bool,
}

impl Regime {
    /// Gradient samples per optimized texel per iteration.
    pub fn samples_per_texel(&self) -> f64 {
        self.pixels as f64 * self.gradient_spp as f64 / self.texels.max(1) as f64
    }

    /// Primal samples per gradient sample.
    pub fn primal_ratio(&self) -> f64 {
        self.primal_spp as f64 / self.gradient_spp.max(1) as f64
    }
}

/// The estimator a run asks for: one by name, or `auto`, chosen by the task's regime
/// ([`MethodChoice::resolve`]). The default of task files and the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum MethodChoice {
    /// Chosen by the regime.
    #[default]
    Auto,
    /// This estimator.
    Fixed(Method),
}

/// What a choice resolved to, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Choice {
    /// The estimator.
    pub method: Method,
    /// Whether `auto` chose it.
    pub automatic: bool,
    /// Why, in one line (the regime's figures and the rule).
    pub reason: String,
}

impl MethodChoice {
    /// `auto`, or the estimator called `name`.
    pub fn by_name(name: &str) -> Option<MethodChoice> {
        if name == "auto" {
            Some(MethodChoice::Auto)
        } else {
            Method::by_name(name).map(MethodChoice::Fixed)
        }
    }

    /// The name used on the command line and in task files.
    pub fn name(self) -> &'static str {
        match self {
            MethodChoice::Auto => "auto",
            MethodChoice::Fixed(m) => m.name(),
        }
    }

    /// Every name a run may ask for: `auto` and each estimator's.
    pub fn names() -> Vec<&'static str> {
        std::iter::once("auto").chain(Method::names()).collect()
    }

    /// The estimator for a task in `regime`.
    pub fn resolve(self, regime: &Regime) -> Choice {
        match self {
            MethodChoice::Fixed(method) => Choice {
                method,
                automatic: false,
                reason: "asked for".into(),
            },
            MethodChoice::Auto => auto(regime),
        }
    }
}

/// The rule: the baseline where texels get about a sample per iteration or more; else
/// ReSTIR where the primal dominates an iteration or the texture is small enough that its
/// merge leaves the budget many iterations; else the baseline.
fn auto(r: &Regime) -> Choice {
    let (d, q) = (r.samples_per_texel(), r.primal_ratio());
    let (method, why) = if r.normal_maps {
        (
            Method::BASELINE,
            "a normal map optimized: with one ReSTIR takes the map's 3x3 derivative in \
             every candidate and merge evaluation, under both iterations' frames (measured \
             on `wall`, 60 s: 2.5x the baseline's time per iteration, 1.41x its base-color \
             error, 14.7 against 9.9 degrees of normal-map error)"
                .to_string(),
        )
    } else if r.recovers_light {
        (
            Method::BASELINE,
            "the environment recovered: every estimator fits the light by plain Monte Carlo, \
             so it converges with the iterations a budget holds (measured on `outdoor`, 30 s: \
             ReSTIR ended at 0.99x the baseline's texture error but 1.55x its image error and \
             1.67x its relit error)"
                .to_string(),
        )
    } else if r.max_depth > 1 {
        (
            Method::BASELINE,
            format!(
                "indirect light (paths of {} vertices): measured with whole paths reused and \
                 each estimator's best step, ReSTIR gained on one indirect-lit bench scene and \
                 lost on the other (0.93x and 1.09x the baseline's texture error)",
                r.max_depth
            ),
        )
    } else if d >= DENSE_SAMPLES_PER_TEXEL {
        (
            Method::BASELINE,
            format!("dense sampling (from {DENSE_SAMPLES_PER_TEXEL}): reuse has little to add"),
        )
    } else if q >= RESTIR_PRIMAL_RATIO {
        (
            Method::RESTIR,
            format!(
                "sparse sampling and an expensive primal (from {RESTIR_PRIMAL_RATIO} primal \
                 samples per gradient sample): ReSTIR's merge adds little to an iteration"
            ),
        )
    } else if r.texels < RESTIR_MAX_TEXELS_CHEAP_PRIMAL {
        (
            Method::RESTIR,
            format!(
                "sparse sampling, {} texels (under {RESTIR_MAX_TEXELS_CHEAP_PRIMAL}): ReSTIR's \
                 merge leaves the budget enough iterations",
                r.texels
            ),
        )
    } else {
        (
            Method::BASELINE,
            format!(
                "sparse sampling but a cheap primal and {} texels (from \
                 {RESTIR_MAX_TEXELS_CHEAP_PRIMAL}): ReSTIR's merge would cost more iterations \
                 than its reuse gains",
                r.texels
            ),
        )
    };
    Choice {
        method,
        automatic: true,
        reason: format!(
            "auto: {d:.2} gradient samples per texel per iteration, {q:.1} primal samples per \
             gradient sample; {why}"
        ),
    }
}

impl std::fmt::Display for MethodChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for MethodChoice {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<MethodChoice> {
        MethodChoice::by_name(s).ok_or_else(|| {
            crate::Error::Invalid(format!(
                "unknown gradient estimator `{s}` (one of: {})",
                MethodChoice::names().join(", ")
            ))
        })
    }
}

impl<'de> serde::Deserialize<'de> for MethodChoice {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<MethodChoice, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

impl serde::Serialize for MethodChoice {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl From<Method> for MethodChoice {
    fn from(m: Method) -> MethodChoice {
        MethodChoice::Fixed(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A task of `pixels` and `texels` at these spp.
    fn regime(primal_spp: u32, gradient_spp: u32, pixels: u64, texels: u64) -> Regime {
        Regime {
            primal_spp,
            gradient_spp,
            pixels,
            texels,
            max_depth: 1,
            recovers_light: false,
            normal_maps: false,
        }
    }

    fn pick(r: Regime) -> Method {
        MethodChoice::Auto.resolve(&r).method
    }

    #[test]
    fn auto_picks_by_density_primal_and_size() {
        // The default task: 2 cameras of 128², 2 gradient spp, 256x128 texels: dense.
        assert_eq!(
            pick(regime(4, 2, 2 * 128 * 128, 256 * 128)),
            Method::BASELINE
        );
        // A bench scene, both protocols: sparse and small.
        assert_eq!(pick(regime(2, 1, 128 * 128, 256 * 256)), Method::RESTIR);
        assert_eq!(pick(regime(32, 1, 128 * 128, 256 * 256)), Method::RESTIR);
        // At scale 4: a cheap primal over 1024² texels takes the baseline, the paper's
        // primal ReSTIR.
        assert_eq!(pick(regime(2, 1, 512 * 512, 1024 * 1024)), Method::BASELINE);
        assert_eq!(pick(regime(32, 1, 512 * 512, 1024 * 1024)), Method::RESTIR);
        assert_eq!(pick(regime(8, 1, 512 * 512, 1024 * 1024)), Method::RESTIR);
        assert_eq!(pick(regime(7, 1, 512 * 512, 1024 * 1024)), Method::BASELINE);
        // The density's threshold: one sample per texel.
        assert_eq!(pick(regime(32, 1, 64 * 64, 64 * 64)), Method::BASELINE);
        assert_eq!(pick(regime(32, 1, 64 * 64 - 1, 64 * 64)), Method::RESTIR);
        let c = MethodChoice::Auto.resolve(&regime(2, 1, 128 * 128, 256 * 256));
        assert!(
            c.automatic && c.reason.contains("0.25 gradient samples"),
            "{c:?}"
        );
        // With indirect light, the baseline whatever the sampling.
        let deep = Regime {
            max_depth: 3,
            ..regime(32, 1, 128 * 128, 256 * 256)
        };
        let c = MethodChoice::Auto.resolve(&deep);
        assert_eq!(c.method, Method::BASELINE);
        assert!(c.reason.contains("3 vertices"), "{c:?}");
        // With the environment recovered, the baseline whatever the sampling (`outdoor`).
        let light = Regime {
            recovers_light: true,
            ..regime(2, 1, 3 * 128 * 128, 2 * 256 * 256)
        };
        let c = MethodChoice::Auto.resolve(&light);
        assert_eq!(c.method, Method::BASELINE);
        assert!(c.reason.contains("environment recovered"), "{c:?}");
        // With a normal map optimized, the baseline whatever the sampling.
        let normals = Regime {
            normal_maps: true,
            ..regime(2, 1, 128 * 128, 256 * 256)
        };
        assert_eq!(
            MethodChoice::Auto.resolve(&normals).method,
            Method::BASELINE
        );
    }

    #[test]
    fn a_named_estimator_is_kept_whatever_the_regime() {
        for m in Method::all() {
            for r in [regime(32, 1, 100, 10_000), regime(2, 2, 10_000, 100)] {
                let c = MethodChoice::Fixed(m).resolve(&r);
                assert_eq!((c.method, c.automatic), (m, false));
            }
        }
    }

    #[test]
    fn names_parse_back_and_unknown_ones_are_refused() {
        for name in MethodChoice::names() {
            let c: MethodChoice = name.parse().unwrap();
            assert_eq!(c.name(), name);
        }
        let e = "restri".parse::<MethodChoice>().unwrap_err().to_string();
        assert!(e.contains("restri") && e.contains("auto"), "{e}");
        #[derive(serde::Deserialize)]
        struct T {
            method: MethodChoice,
        }
        let t: T = toml::from_str("method = \"auto\"").unwrap();
        assert_eq!(t.method, MethodChoice::Auto);
        let t: T = toml::from_str("method = \"restir\"").unwrap();
        assert_eq!(t.method, MethodChoice::Fixed(Method::RESTIR));
        assert!(toml::from_str::<T>("method = \"fast\"").is_err());
    }
}
