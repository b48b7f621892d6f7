//! The `catalogue!` macro: from one list of commands (`commands.rs`), the [`Command`]
//! enum, its tags, names, wire encoding and decoding, and the [`CommandKind`] table.
//!
//! [`Command`]: super::Command
//! [`CommandKind`]: super::CommandKind

/// Expands the command list of `commands.rs`. Each entry: the variant's docs,
/// `#[kind(CONST = tag, name = "...", original = "...")]`, `#[wire = "..."]` (the doc of its
/// `kind::CONST`), then the variant, unit or with fields `name: type as (params)`, the
/// params being the field's names in the bindings (three for a `Vec3`).
macro_rules! catalogue {
    ($(
        $(#[doc = $doc:literal])*
        #[kind($tag_name:ident = $tag:literal, name = $name:literal, original = $original:literal)]
        #[wire = $wire:literal]
        $variant:ident $({
            $( $(#[doc = $fdoc:literal])* $field:ident : $ty:ty as ($($param:ident),+) ),* $(,)?
        })?
    ),* $(,)?) => {
        catalogue!(@tags $( [$wire] $tag_name = $tag; )*);
        catalogue!(@enum $( [$($doc)*] $variant $({ $( [$($fdoc)*] $field: $ty ),* })?; )*);
        catalogue!(@codec $( $tag_name $variant $({ $( $field: $ty ),* })?; )*);
        catalogue!(@table $(
            $tag_name $name $original $variant [$($( $ty as ($($param),+) )*)?];
        )*);
    };

    (@tags $( [$wire:literal] $tag_name:ident = $tag:literal; )*) => {
        /// Wire tags of [`MotorCommand::kind`], one per variant of [`Command`].
        pub mod kind {
            $( #[doc = $wire] pub const $tag_name: u32 = $tag; )*
        }
    };

    (@enum $(
        [$($doc:literal)*] $variant:ident $({ $( [$($fdoc:literal)*] $field:ident : $ty:ty ),* })?;
    )*) => {
        /// A motor command, typed. The catalogue follows the original system's messages.
        #[derive(Debug, Clone, Copy, PartialEq)]
        pub enum Command {
            $( $(#[doc = $doc])* $variant $({ $( $(#[doc = $fdoc])* $field: $ty ),* })?, )*
        }
    };

    (@codec $( $tag_name:ident $variant:ident $({ $( $field:ident : $ty:ty ),* })?; )*) => {
        impl Command {
            /// The wire tag of this command.
            pub fn kind(&self) -> u32 {
                match self {
                    $( Self::$variant { .. } => kind::$tag_name, )*
                }
            }

            /// A short lowercase name, for logs and recordings.
            pub fn name(&self) -> &'static str {
                kind_name(self.kind())
            }

            /// Encodes this command with the given action id.
            pub fn encode(&self, action_id: u32) -> MotorCommand {
                let mut m = MotorCommand {
                    kind: self.kind(),
                    action_id,
                    ..MotorCommand::default()
                };
                let at = &mut 0;
                match *self {
                    $( Self::$variant { $($( $field ),*)? } => {
                        $($( WireField::put($field, &mut m, at); )*)?
                    } )*
                }
                m
            }
        }

        impl MotorCommand {
            /// Decodes the typed command. Unknown tags and non-finite arguments are errors;
            /// range checks belong to the simulator, which knows its world.
            ///
            /// # Errors
            /// [`CommandDecodeError`] naming the tag, the action id and what is wrong.
            pub fn decode(&self) -> Result<Command, CommandDecodeError> {
                let at = &mut 0;
                Ok(match self.kind {
                    $( kind::$tag_name => {
                        check_finite(self, 0 $($( + <$ty as WireField>::ARGS )*)?)?;
                        Command::$variant { $($( $field: WireField::get(self, at) ),*)? }
                    } )*
                    other => {
                        return Err(CommandDecodeError::UnknownKind {
                            kind: other,
                            action_id: self.action_id,
                        });
                    }
                })
            }
        }
    };

    (@table $(
        $tag_name:ident $name:literal $original:literal $variant:ident
        [$( $ty:ty as ($($param:ident),+) )*];
    )*) => {
        /// The lowercase name of a wire tag (`"unknown"` for unknown tags).
        pub fn kind_name(tag: u32) -> &'static str {
            match tag {
                $( kind::$tag_name => $name, )*
                _ => "unknown",
            }
        }

        impl CommandKind {
            /// Every kind of the catalogue, in tag order: the one list the bindings are
            /// checked against.
            pub const ALL: &'static [CommandKind] = &[$(
                CommandKind {
                    tag: kind::$tag_name,
                    name: $name,
                    variant: stringify!($variant),
                    original: $original,
                    arg_count: 0 $( + <$ty as WireField>::ARGS )*,
                    params: &[$($(
                        CommandParam {
                            name: stringify!($param),
                            ty: <$ty as WireField>::PARAM,
                        },
                    )+)*],
                },
            )*];
        }

        // Each kind fits the wire form: at most 4 args and one `object_id`, and a field has
        // as many binding names as parameters.
        const _: () = {$(
            assert!(0 $( + <$ty as WireField>::ARGS )* <= 4);
            assert!(0 $( + (<$ty as WireField>::ARGS == 0) as usize )* <= 1);
            $( assert!(<$ty as WireField>::PARAMS == [$(stringify!($param)),+].len()); )*
        )*};
    };
}
