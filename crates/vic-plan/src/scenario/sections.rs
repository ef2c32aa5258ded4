//! The shape of a scenario file: its sections, and the key that selects each tagged section's
//! variant. Read by the raw types and by the error messages alike.

/// The sections of a scenario file, in the order they are usually written.
pub(super) const SECTIONS: [&str; 8] = [
    "plant", "actuator", "field", "noise", "cost", "task", "solver", "board",
];

/// The sections whose variant a key selects, and that key.
pub(super) const TAGGED: [(&str, &str); 4] = [
    ("plant", "kind"),
    ("actuator", "type"),
    ("field", "kind"),
    ("noise", "kind"),
];

/// The key that selects the variant of `section`, if it has one.
pub(super) fn tag_of(section: &str) -> Option<&'static str> {
    TAGGED.iter().find(|(s, _)| *s == section).map(|(_, t)| *t)
}
