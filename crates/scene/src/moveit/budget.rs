//! The YAML resource budget of a planning scene or motion-plan request, in proportion to its
//! text (the module docs of [`super`]), and the object limit enforced while the scene is parsed.

use super::{RawObject, MAX_SCENE_ITEMS};
use crate::{Error, Result};
use serde::Deserialize;
use std::cell::Cell;

/// What every YAML text may spend, whatever its size, beyond its proportional budget
/// ([`YamlBudget::for_text`]): parser events, nodes, and replayed alias events.
pub const YAML_BUDGET_BASE: usize = 4096;

/// The resource budget of one YAML parse ([`YamlBudget::for_text`]), checked by the parser as it
/// reads, before the events it counts are kept or expanded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct YamlBudget {
    /// Most parser events (every event, alias replays included).
    pub max_events: usize,
    /// Most nodes (scalars, sequence and mapping starts; alias replays included).
    pub max_nodes: usize,
    /// Most events replayed through aliases, all aliases together.
    pub max_replayed_events: usize,
    /// Most event copies kept for anchors (each copy into each open anchored node counted).
    pub max_recorded_anchor_events: usize,
    /// Most bytes of scalar text (alias replays included).
    pub max_scalar_bytes: usize,
}

impl YamlBudget {
    /// The budget of a text of `len` bytes: 3·len + [`YAML_BUDGET_BASE`] events and nodes,
    /// len + [`YAML_BUDGET_BASE`] replayed and recorded alias events, 4·len +
    /// [`YAML_BUDGET_BASE`] scalar bytes (module docs).
    pub fn for_text(len: usize) -> Self {
        let per = |k: usize| len.saturating_mul(k).saturating_add(YAML_BUDGET_BASE);
        Self {
            max_events: per(3),
            max_nodes: per(3),
            max_replayed_events: per(1),
            max_recorded_anchor_events: per(1),
            max_scalar_bytes: per(4),
        }
    }

    /// The parser options that enforce it (serde-saphyr's budget and alias limits; everything else
    /// at its default).
    fn options(&self) -> serde_saphyr::Options {
        let mut budget = serde_saphyr::Budget::default();
        budget.max_events = self.max_events;
        budget.max_nodes = self.max_nodes;
        budget.max_recorded_anchor_events = self.max_recorded_anchor_events;
        budget.max_total_scalar_bytes = self.max_scalar_bytes;
        let mut options = serde_saphyr::Options::default();
        options.budget = Some(budget);
        options.alias_limits.max_total_replayed_events = self.max_replayed_events;
        options
    }
}

/// Reads YAML `bytes` into `T` under the budget of their length ([`YamlBudget::for_text`]).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field`, with the parser's message (and the budget when it
/// was breached).
pub(crate) fn parse_yaml<'de, T: Deserialize<'de>>(field: &str, bytes: &'de [u8]) -> Result<T> {
    let budget = YamlBudget::for_text(bytes.len());
    serde_saphyr::from_slice_with_options(bytes, budget.options()).map_err(|e| {
        let text = e.to_string();
        if text.contains("budget") || text.contains("replay") || text.contains("alias") {
            Error::invalid(
                field,
                format!(
                    "{text} (the budget of a {}-byte text: at most {} events, {} replayed alias events)",
                    bytes.len(),
                    budget.max_events,
                    budget.max_replayed_events
                ),
            )
        } else {
            Error::invalid(field, text)
        }
    })
}

thread_local! {
    /// The object limit of the parse running on this thread ([`with_object_limit`]): a derived
    /// field deserializer takes no argument, so the limit travels beside it.
    static OBJECT_LIMIT: Cell<usize> = const { Cell::new(MAX_SCENE_ITEMS) };
    /// Set when that parse met more objects than its limit.
    static OBJECTS_OVER: Cell<bool> = const { Cell::new(false) };
}

/// Runs `parse` with `world.collision_objects` bounded to `max_objects` elements: the parser
/// stops at the first one past it, so a scene over the limit costs no more than one at it.
pub(super) fn with_object_limit<T>(max_objects: usize, parse: impl FnOnce() -> Result<T>) -> Result<T> {
    let before = OBJECT_LIMIT.with(|l| l.replace(max_objects));
    OBJECTS_OVER.with(|o| o.set(false));
    let out = parse();
    OBJECT_LIMIT.with(|l| l.set(before));
    if OBJECTS_OVER.with(|o| o.replace(false)) {
        return Err(Error::ResourceExhausted(format!(
            "`world.collision_objects` holds more than {max_objects} collision objects, the most one scene may hold"
        )));
    }
    out
}

/// `world.collision_objects`, refused at the first element past [`OBJECT_LIMIT`].
pub(super) fn bounded_objects<'de, D: serde::Deserializer<'de>>(
    deserializer: D,
) -> std::result::Result<Vec<RawObject>, D::Error> {
    struct Visitor;
    impl<'de> serde::de::Visitor<'de> for Visitor {
        type Value = Vec<RawObject>;
        fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("a list of collision objects")
        }
        fn visit_unit<E: serde::de::Error>(self) -> std::result::Result<Self::Value, E> {
            Ok(Vec::new())
        }
        fn visit_none<E: serde::de::Error>(self) -> std::result::Result<Self::Value, E> {
            Ok(Vec::new())
        }
        fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<Self::Value, A::Error> {
            let max = OBJECT_LIMIT.with(Cell::get);
            let mut out = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(max).min(4096));
            while let Some(object) = seq.next_element::<RawObject>()? {
                if out.len() >= max {
                    OBJECTS_OVER.with(|o| o.set(true));
                    return Err(serde::de::Error::custom(format!("more than {max} collision objects")));
                }
                out.push(object);
            }
            Ok(out)
        }
    }
    deserializer.deserialize_seq(Visitor)
}
