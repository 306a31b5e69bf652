//! The scene's typed choices: the solver's precision and integration (the firmware's own
//! enums, spelled "f64" | "f32" and "reduced" | "full" in scene files, manifests and
//! reports) and the material law, each with its TOML spelling, and their command-line forms.

use pe_firmware::image::{Integration, Precision};
use pe_firmware::physics::HourglassControl;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// One of a closed set of names: parsed from and written as its text.
trait Named: Sized + Copy + 'static {
    /// What the value is ("precision", "law", ...), for error messages.
    const WHAT: &'static str;
    const ALL: &'static [Self];
    fn name(self) -> &'static str;

    fn from_name(text: &str) -> Result<Self, String> {
        Self::ALL
            .iter()
            .copied()
            .find(|v| v.name() == text)
            .ok_or_else(|| {
                let allowed: Vec<String> = Self::ALL
                    .iter()
                    .map(|v| format!("\"{}\"", v.name()))
                    .collect();
                format!(
                    "unknown {} \"{text}\": expected {}",
                    Self::WHAT,
                    allowed.join(" | ")
                )
            })
    }
}

impl Named for Precision {
    const WHAT: &'static str = "precision";
    const ALL: &'static [Self] = &[Precision::F64, Precision::F32];
    fn name(self) -> &'static str {
        Precision::name(self)
    }
}

impl Named for Integration {
    const WHAT: &'static str = "integration";
    const ALL: &'static [Self] = &[Integration::Reduced, Integration::Full];
    fn name(self) -> &'static str {
        Integration::name(self)
    }
}

fn serialize_named<S: Serializer, T: Named>(v: &T, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(v.name())
}

fn deserialize_named<'de, D: Deserializer<'de>, T: Named>(d: D) -> Result<T, D::Error> {
    let text = String::deserialize(d)?;
    T::from_name(&text).map_err(serde::de::Error::custom)
}

/// Precision parsed from its name ("f32" | "f64"), e.g. a manifest's.
pub fn precision_from_name(text: &str) -> Result<Precision, String> {
    Precision::from_name(text)
}

/// `#[serde(with = "precision_text")]`: a [`Precision`] as "f64" | "f32".
pub mod precision_text {
    use super::*;
    pub fn serialize<S: Serializer>(v: &Precision, s: S) -> Result<S::Ok, S::Error> {
        serialize_named(v, s)
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Precision, D::Error> {
        deserialize_named(d)
    }
}

/// `#[serde(with = "integration_text")]`: an [`Integration`] as "reduced" | "full".
pub mod integration_text {
    use super::*;
    pub fn serialize<S: Serializer>(v: &Integration, s: S) -> Result<S::Ok, S::Error> {
        serialize_named(v, s)
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Integration, D::Error> {
        deserialize_named(d)
    }
}

/// `#[serde(with = "hourglass_text")]`: a [`HourglassControl`] as `"physical"` or the
/// scalar form's coefficient `κ_hg` (a number).
pub mod hourglass_text {
    use super::*;
    pub fn serialize<S: Serializer>(v: &HourglassControl, s: S) -> Result<S::Ok, S::Error> {
        match v {
            HourglassControl::Physical => s.serialize_str("physical"),
            HourglassControl::Scalar(k) => s.serialize_f64(*k),
        }
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<HourglassControl, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Text {
            Name(String),
            Coefficient(f64),
        }
        match Text::deserialize(d)? {
            Text::Coefficient(k) => coefficient(k),
            Text::Name(n) => hourglass_from_text(&n),
        }
        .map_err(serde::de::Error::custom)
    }
}

/// A hourglass control from its text: `"physical"` or a coefficient (`"0.1"`), e.g. a
/// command line's.
pub fn hourglass_from_text(text: &str) -> Result<HourglassControl, String> {
    if text == "physical" {
        return Ok(HourglassControl::Physical);
    }
    match text.parse::<f64>() {
        Ok(k) => coefficient(k),
        Err(_) => Err(format!(
            "hourglass \"{text}\": expected \"physical\" or the scalar form's coefficient (a number, e.g. 0.1)"
        )),
    }
}

/// The scalar form's coefficient `k`, refused unless finite and `>= 0`.
fn coefficient(k: f64) -> Result<HourglassControl, String> {
    if k >= 0.0 && k.is_finite() {
        Ok(HourglassControl::Scalar(k))
    } else {
        Err(format!(
            "hourglass must be \"physical\" or a coefficient >= 0, got {k}"
        ))
    }
}

/// The hyperelastic law of a `[material]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Law {
    NeoHookean,
    NeoHookeanDecoupled,
    MooneyRivlin,
}

impl Named for Law {
    const WHAT: &'static str = "law";
    const ALL: &'static [Self] = &[Law::NeoHookean, Law::NeoHookeanDecoupled, Law::MooneyRivlin];
    fn name(self) -> &'static str {
        Law::name(self)
    }
}

impl Law {
    /// The scene file's spelling.
    pub const fn name(self) -> &'static str {
        match self {
            Law::NeoHookean => "neo-hookean",
            Law::NeoHookeanDecoupled => "neo-hookean-decoupled",
            Law::MooneyRivlin => "mooney-rivlin",
        }
    }
}

impl std::fmt::Display for Law {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Serialize for Law {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        serialize_named(self, s)
    }
}

impl<'de> Deserialize<'de> for Law {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Law, D::Error> {
        deserialize_named(d)
    }
}

/// `--precision f32|f64` on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PrecisionArg {
    F32,
    F64,
}

impl From<PrecisionArg> for Precision {
    fn from(p: PrecisionArg) -> Precision {
        match p {
            PrecisionArg::F32 => Precision::F32,
            PrecisionArg::F64 => Precision::F64,
        }
    }
}

/// `--integration reduced|full` on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum IntegrationArg {
    Reduced,
    Full,
}

impl From<IntegrationArg> for Integration {
    fn from(i: IntegrationArg) -> Integration {
        match i {
            IntegrationArg::Reduced => Integration::Reduced,
            IntegrationArg::Full => Integration::Full,
        }
    }
}
