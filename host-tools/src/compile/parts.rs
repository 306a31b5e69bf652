//! The firmware's parts ([`Feature`]: contact, graphics, loads; cargo features of
//! `pe-firmware` and the board crate) a set of images needs: the compile report's per board,
//! and the build `pe image` makes, which carries no other.

use pe_firmware::image::{Feature, ImageHeader};

/// The parts some image of `headers` needs, in [`Feature::ALL`] order (a scene without
/// contact gets a firmware without its code and tables; a board's image without contact
/// tables runs none of it either way).
pub fn parts_of<'h>(headers: impl Iterator<Item = &'h ImageHeader> + Clone) -> Vec<Feature> {
    Feature::ALL
        .into_iter()
        .filter(|&f| headers.clone().any(|h| h.uses(f).is_some()))
        .collect()
}

/// [`parts_of`] by name (the cargo features).
pub fn parts_needed<'h>(
    headers: impl Iterator<Item = &'h ImageHeader> + Clone,
) -> Vec<&'static str> {
    parts_of(headers).into_iter().map(Feature::name).collect()
}

/// `#[serde(with = "feature_names")]`: a list of parts as their names; reading a name that
/// is no part is an error naming it and the parts.
pub mod feature_names {
    use pe_firmware::image::Feature;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(parts: &[Feature], s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(parts.iter().map(|f| f.name()))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Feature>, D::Error> {
        Vec::<String>::deserialize(d)?
            .iter()
            .map(|name| {
                Feature::ALL
                    .into_iter()
                    .find(|f| f.name() == name)
                    .ok_or_else(|| {
                        let known: Vec<&str> = Feature::ALL.map(Feature::name).to_vec();
                        serde::de::Error::custom(format!(
                            "unknown firmware part {name:?} (known: {})",
                            known.join(", ")
                        ))
                    })
            })
            .collect()
    }
}
