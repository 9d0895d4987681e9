//! The frame's uniform (`FrameUniform` in `shaders/frame_uniform.wgsl`), read by name in every pass
//! that needs the frame's sizes, and its Rust twin, written as one value.

/// `shaders/frame_uniform.wgsl`, put before each shader that binds the frame's uniform.
pub const WGSL: &str = include_str!("shaders/frame_uniform.wgsl");

/// A `#[repr(C)]` struct of `u32` fields, with its fields' names and byte offsets (compared
/// with the WGSL struct's by a test) and its words in field order (what the buffer holds).
macro_rules! uniform_struct {
    ($(#[$meta:meta])* pub struct $name:ident { $($(#[$field_meta:meta])* pub $field:ident: u32,)* }) => {
        $(#[$meta])*
        #[repr(C)]
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
        pub struct $name { $($(#[$field_meta])* pub $field: u32,)* }

        impl $name {
            /// Each field's name and byte offset, in order.
            pub const FIELDS: &[(&str, usize)] =
                &[$((stringify!($field), std::mem::offset_of!($name, $field))),*];
            /// Its size in 32-bit words.
            pub const WORDS: usize = std::mem::size_of::<$name>() / 4;

            /// The words a uniform buffer holds for it.
            pub fn words(&self) -> Vec<u32> {
                vec![$(self.$field),*]
            }
        }
    };
}

uniform_struct! {
    /// What the passes of one frame share (WGSL `FrameUniform`).
    pub struct FrameUniform {
        pub primitives: u32,
        pub width: u32,
        pub height: u32,
        pub tile_size: u32,
        pub tiles_x: u32,
        pub p_max: u32,
        pub tiles: u32,
        /// The tile keys the buffers hold: written alone when they grow ([`FrameUniform::ROOM`]).
        pub room: u32,
    }
}

impl FrameUniform {
    /// The byte offset of `room`, which the front writes on its own.
    pub const ROOM: u64 = std::mem::offset_of!(FrameUniform, room) as u64;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The WGSL struct named `name` in `source`: its members' names and byte offsets, as
    /// naga lays them out.
    fn wgsl_fields(source: &str, name: &str) -> Vec<(String, usize)> {
        let module = naga::front::wgsl::parse_str(source).expect("the WGSL parses");
        let ty = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("no struct {name}"));
        let naga::TypeInner::Struct { members, .. } = &ty.1.inner else {
            panic!("{name} is not a struct");
        };
        members
            .iter()
            .map(|m| (m.name.clone().unwrap(), m.offset as usize))
            .collect()
    }

    /// The Rust twin's fields and byte offsets, as [`wgsl_fields`] lists them.
    fn rust_fields() -> Vec<(String, usize)> {
        let fields = FrameUniform::FIELDS.iter();
        fields.map(|(n, o)| (n.to_string(), *o)).collect()
    }

    #[test]
    fn the_rust_twin_lays_out_as_the_wgsl_struct() {
        assert_eq!(rust_fields(), wgsl_fields(WGSL, "FrameUniform"));
        assert_eq!(FrameUniform::WORDS * 4, std::mem::size_of::<FrameUniform>());
    }

    #[test]
    fn a_field_out_of_place_is_caught() {
        let swapped = WGSL.replace(
            "    width: u32,\n    height: u32,",
            "    height: u32,\n    width: u32,",
        );
        assert_ne!(swapped, WGSL);
        assert_ne!(rust_fields(), wgsl_fields(&swapped, "FrameUniform"));
    }
}
