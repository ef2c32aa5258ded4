//! Enums that travel as integers: the variants with their wire values and report names written
//! once, and what every such enum needs from them (the list of variants, the variant of a wire
//! value, the name).

/// Declares a fieldless enum with explicit wire values (`Variant = value => "name"`), and in
/// its `impl`: `COUNT`, `ALL` (every variant in declaration order), `from_wire` (the variant of
/// a wire value, `None` for an unknown one) and `name` (lower-case, for reports and JSON).
/// With `else Variant` after the representation, also `from_u32`: the variant of a wire value,
/// unknown values read as that one.
macro_rules! wire_enum {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident : $repr:ident else $fallback:ident {
            $( $(#[$vmeta:meta])* $variant:ident = $value:literal => $label:literal, )+
        }
    ) => {
        wire_enum! {
            $(#[$meta])*
            $vis enum $name: $repr {
                $( $(#[$vmeta])* $variant = $value => $label, )+
            }
        }

        impl $name {
            /// The variant of the wire value `v`; unknown values read as
            #[doc = concat!("`", stringify!($fallback), "`.")]
            pub fn from_u32(v: u32) -> $name {
                $name::from_wire(v).unwrap_or($name::$fallback)
            }
        }
    };
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident : $repr:ident {
            $( $(#[$vmeta:meta])* $variant:ident = $value:literal => $label:literal, )+
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        #[repr($repr)]
        $vis enum $name {
            $( $(#[$vmeta])* $variant = $value, )+
        }

        impl $name {
            /// Number of variants.
            pub const COUNT: usize = [$($name::$variant),+].len();
            /// Every variant, in declaration order.
            pub const ALL: [$name; $name::COUNT] = [$($name::$variant),+];

            /// The variant whose wire value is `v` (`None`: no such variant).
            pub fn from_wire(v: u32) -> Option<$name> {
                $(
                    if v == $name::$variant as u32 {
                        return Some($name::$variant);
                    }
                )+
                None
            }

            /// Lower-case name for reports and JSON.
            pub fn name(self) -> &'static str {
                match self {
                    $( $name::$variant => $label, )+
                }
            }
        }
    };
}

pub(crate) use wire_enum;
