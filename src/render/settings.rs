//! Guiding settings by name: one definition per setting (its key, the value it takes, its help
//! and how it sets [`GuidingOptions`]) that the CLI's flags (`--alpha 0.6`), `compare`'s
//! method keys (`alpha:0.6`) and programs reading settings as text all use, so a setting has
//! one name, one grammar and one rule everywhere. The rules themselves are
//! [`GuidingOptions::validate`]'s, whichever way the options were assembled.

use super::options::{GuidingOptions, OptionsError, TrainBudget, parse_guiding};
use std::time::Duration;

/// One guiding setting.
#[derive(Debug)]
pub struct Setting {
    /// Its name: `--KEY` on the command line, `KEY:VALUE` in a `compare` method.
    pub key: &'static str,
    /// What the value is, for help texts (`P`, `MODE`, ...).
    pub value: &'static str,
    /// What it does, and its default.
    pub help: &'static str,
    /// Whether it concerns training, so that `zerovar train` takes it (the others only matter
    /// to a render).
    pub trains: bool,
    set: fn(&mut GuidingOptions, &str) -> Result<(), &'static str>,
}

/// A setting given as text that could not be applied.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SettingError {
    /// No setting has this key.
    #[error("unknown setting `{key}`; the settings are {known}")]
    Unknown {
        /// The key given.
        key: String,
        /// Every key, comma-separated.
        known: String,
    },
    /// The value is not of the setting's kind.
    #[error("{key} `{value}`: {expected}")]
    Value {
        /// The setting.
        key: &'static str,
        /// The value given.
        value: String,
        /// What the setting takes.
        expected: &'static str,
    },
    /// A setting given twice.
    #[error("{0} is given twice: give it once")]
    Twice(&'static str),
    /// Two settings given together that choose the same thing.
    #[error("{0} and {1} both choose the training budget: give one of them")]
    Conflict(&'static str, &'static str),
    /// The value parsed but breaks a rule of the options.
    #[error(transparent)]
    Invalid(#[from] OptionsError),
}

/// The settings that choose the training budget; at most one may be given.
pub const TRAIN_BUDGET: [&str; 3] = ["train-share", "train-passes", "train-time"];

/// Every guiding setting, in the order help texts list them.
pub const SETTINGS: &[Setting] = &[
    Setting {
        key: "guiding",
        value: "MODE",
        help: "Guided decisions: off, directions, distances, rr, full, or a +-joined list \
               (e.g. directions+rr); auto is full guiding (or roulette alone, where that pays \
               better) in the tiles where a pilot finds it pays, and unguided sampling \
               elsewhere [default: auto; full for `train` and with --field]",
        trains: true,
        set: |o, v| {
            let (components, adaptive) = parse_guiding(v).ok_or(
                "give off, directions, distances, rr, full, auto, or a +-joined list of them",
            )?;
            (o.components, o.adaptive) = (components, adaptive);
            Ok(())
        },
    },
    Setting {
        key: "alpha",
        value: "P",
        help: "Probability of the guided strategy in each mixture with standard sampling in \
               media, in [0, 0.8]: standard sampling always keeps at least 20%, which bounds \
               every guided weight [default: 0.5]",
        trains: true,
        set: |o, v| {
            o.alpha = number(v)? as f32;
            Ok(())
        },
    },
    Setting {
        key: "surface-alpha",
        value: "P",
        help: "The same at surfaces, in [0, 0.8] [default: 0.7]",
        trains: true,
        set: |o, v| {
            o.surface_alpha = number(v)? as f32;
            Ok(())
        },
    },
    Setting {
        key: "distance-alpha",
        value: "P",
        help: "Probability of the zero-variance collision density in guided flights' mixture \
               with standard tracking, in [0, 0.8]; guided flights take extra collisions for \
               delta lights whatever it is [default: 0, which spares each flight a field lookup]",
        trains: true,
        set: |o, v| {
            o.distance_alpha = number(v)? as f32;
            Ok(())
        },
    },
    Setting {
        key: "collision-windows",
        value: "ON|OFF",
        help: "Weight windows also after each medium collision, before its next-event \
               estimate, besides the one after each direction (on; needs rr guided), or after \
               directions only [default: off; see docs/experiments.md]",
        trains: true,
        set: |o, v| {
            o.collision_windows = match v.trim() {
                "on" => true,
                "off" => false,
                _ => return Err("give on or off"),
            };
            Ok(())
        },
    },
    Setting {
        key: "train-share",
        value: "F",
        help: "Share of the budget (--time or --spp) that training takes, in (0, 1): doubling \
               passes of 1, 2, 4, ... samples per pixel while the next fits in it; the render \
               gets the rest [default: 0.25]",
        trains: true,
        set: |o, v| {
            o.train = TrainBudget::Share(number(v)? as f32);
            Ok(())
        },
    },
    Setting {
        key: "train-passes",
        value: "N",
        help: "Train this many passes instead, 1 to 20 (with --spp, the render then renders \
               all of it)",
        trains: true,
        set: |o, v| {
            let n = v.trim().parse::<u32>().map_err(|_| "give a whole number of passes")?;
            o.train = TrainBudget::Passes(n);
            Ok(())
        },
    },
    Setting {
        key: "train-time",
        value: "SECONDS",
        help: "Train for this many seconds instead (doubling passes; --time still includes \
               them)",
        trains: true,
        set: |o, v| {
            let t = number(v)?;
            let t =
                Duration::try_from_secs_f64(t).map_err(|_| "give a positive number of seconds")?;
            o.train = TrainBudget::Time(t);
            Ok(())
        },
    },
    Setting {
        key: "training-images",
        value: "WHAT",
        help: "What becomes of the training passes' images: combine (averaged into the result \
               by inverse variance, each half of an image weighed by the other's) or discard \
               [default: combine]",
        trains: false,
        set: |o, v| {
            o.combine_training = match v.trim() {
                "combine" => true,
                "discard" => false,
                _ => return Err("give combine or discard"),
            };
            Ok(())
        },
    },
    Setting {
        key: "parallax",
        value: "ON|OFF",
        help: "Parallax-aware lobes: each learns how far its light comes from and is re-aimed \
               at it from every point of its region (on), or fixed directions per region (off, \
               for comparison) [default: on]",
        trains: true,
        set: |o, v| {
            o.field.parallax = match v.trim() {
                "on" => true,
                "off" => false,
                _ => return Err("give on or off"),
            };
            Ok(())
        },
    },
];

/// A number, for the settings that take one.
fn number(v: &str) -> Result<f64, &'static str> {
    v.trim().parse::<f64>().map_err(|_| "give a number")
}

/// The setting named `key`.
pub fn setting(key: &str) -> Option<&'static Setting> {
    SETTINGS.iter().find(|s| s.key == key)
}

impl GuidingOptions {
    /// Applies settings given as text, in order, over these options, and checks the result
    /// ([`GuidingOptions::validate`]). Refused: unknown keys, values of the wrong kind, and
    /// two settings that choose the same thing (a key twice, or two training budgets).
    pub fn apply<'a>(
        &mut self,
        settings: impl IntoIterator<Item = (&'a str, &'a str)>,
    ) -> Result<(), SettingError> {
        let mut given: Vec<&'static str> = Vec::new();
        for (key, value) in settings {
            let Some(s) = setting(key) else {
                let known = SETTINGS.iter().map(|s| s.key).collect::<Vec<_>>().join(", ");
                return Err(SettingError::Unknown { key: key.to_string(), known });
            };
            for &other in &given {
                if other == s.key {
                    return Err(SettingError::Twice(s.key));
                }
                if TRAIN_BUDGET.contains(&other) && TRAIN_BUDGET.contains(&s.key) {
                    return Err(SettingError::Conflict(other, s.key));
                }
            }
            given.push(s.key);
            (s.set)(self, value).map_err(|expected| SettingError::Value {
                key: s.key,
                value: value.to_string(),
                expected,
            })?;
        }
        self.validate()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every setting takes a good value, names itself on a bad one, and the options after a
    /// good one are the ones the field would hold set directly.
    #[test]
    fn settings_set_what_they_name_and_refuse_what_they_cannot() {
        let good = [
            ("guiding", "directions+rr"),
            ("alpha", "0.6"),
            ("surface-alpha", "0.3"),
            ("distance-alpha", "0.2"),
            ("collision-windows", "on"),
            ("train-share", "0.4"),
            ("train-passes", "3"),
            ("train-time", "1.5"),
            ("training-images", "discard"),
            ("parallax", "off"),
        ];
        assert_eq!(good.len(), SETTINGS.len(), "a setting without a test case");
        for (key, value) in good {
            let mut o = GuidingOptions::auto();
            o.apply([(key, value)]).unwrap_or_else(|e| panic!("{key} {value}: {e}"));
            assert_ne!(format!("{o:?}"), format!("{:?}", GuidingOptions::auto()), "{key}");
            let mut bad = GuidingOptions::auto();
            let e = bad.apply([(key, "sideways")]).unwrap_err();
            assert!(e.to_string().starts_with(&format!("{key} `sideways`: give")), "{e}");
        }
        let mut o = GuidingOptions::auto();
        o.apply([("alpha", "0.6"), ("train-passes", "3"), ("parallax", "off")]).unwrap();
        assert_eq!((o.alpha, o.train, o.field.parallax), (0.6, TrainBudget::Passes(3), false));
    }

    /// Values of the right kind that break a rule are refused by the rule's own error, and
    /// settings that choose one thing twice are refused together.
    #[test]
    fn rules_and_conflicts_are_refused() {
        let cases: [(&[(&str, &str)], &str); 8] = [
            (&[("alpha", "1.5")], "alpha 1.5: give a probability in [0, 0.8]"),
            (&[("surface-alpha", "0.9")], "surface-alpha 0.9"),
            (&[("distance-alpha", "-1")], "distance-alpha -1"),
            (&[("train-passes", "0")], "train-passes 0"),
            (&[("train-share", "1")], "train-share 1"),
            (&[("train-share", "0.2"), ("train-time", "3")], "train-share and train-time both"),
            (&[("alpha", "0.2"), ("alpha", "0.3")], "alpha is given twice"),
            (
                &[("guiding", "directions"), ("collision-windows", "on")],
                "collision-windows on needs guided roulette",
            ),
        ];
        for (settings, needle) in cases {
            let e = GuidingOptions::auto().apply(settings.iter().copied()).unwrap_err();
            assert!(e.to_string().contains(needle), "{settings:?}: {e}");
        }
        let e = GuidingOptions::auto().apply([("alpah", "0.5")]).unwrap_err();
        assert!(e.to_string().contains("unknown setting `alpah`; the settings are guiding, alpha"));
    }
}
