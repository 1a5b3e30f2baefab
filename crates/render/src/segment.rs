//! Segmentation ids: what each pixel of the segmentation image shows.
//!
//! | id            | part                                                    |
//! |---------------|---------------------------------------------------------|
//! | 0             | background (nothing hit)                                |
//! | 1             | the table                                               |
//! | 2 + j         | bin `j` (index in `scene.bins`), j < 30                 |
//! | 32 + i        | object `i` (index in `scene.objects`), i < 32           |
//! | 64 + l        | robot link `l` (index in the robot model's links: arm   |
//! |               | and gripper, e.g. `left_finger`)                        |
//!
//! Links without a shape (`tool0`, `tcp`) never appear. With the bundled FR5 and gripper:
//! 64–70 `base_link`…`wrist3_link`, 72 `gripper_base`, 73/74 the left/right finger.
//! [`crate::segment_name`] names an id.

use crate::error::{RenderError, Result};

/// Id of pixels that show nothing.
pub const BACKGROUND: u16 = 0;
/// Id of the table.
pub const TABLE: u16 = 1;
/// Id of bin 0; bin `j` is `FIRST_BIN + j`.
pub const FIRST_BIN: u16 = 2;
/// Id of object 0; object `i` is `FIRST_OBJECT + i`.
pub const FIRST_OBJECT: u16 = 32;
/// Id of robot link 0; link `l` is `FIRST_LINK + l`.
pub const FIRST_LINK: u16 = 64;

/// A part of the scene as the segmentation image tells it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Segment {
    /// Nothing hit.
    Background,
    /// The table.
    Table,
    /// A bin, by its index in the scene's bins.
    Bin(usize),
    /// An object, by its index in the scene's objects.
    Object(usize),
    /// Index into the robot model's links.
    Link(usize),
}

impl Segment {
    /// The id of this part; an error when its index does not fit its range.
    pub fn id(self) -> Result<u16> {
        let (first, end, index, what) = match self {
            Segment::Background => return Ok(BACKGROUND),
            Segment::Table => return Ok(TABLE),
            Segment::Bin(j) => (FIRST_BIN, FIRST_OBJECT, j, "bins"),
            Segment::Object(i) => (FIRST_OBJECT, FIRST_LINK, i, "objects"),
            Segment::Link(l) => (FIRST_LINK, u16::MAX, l, "robot links"),
        };
        let room = (end - first) as usize;
        if index >= room {
            return Err(RenderError::Segmentation(format!(
                "the scene has more than {room} {what}; the segmentation ids hold at most {room}"
            )));
        }
        Ok(first + index as u16)
    }

    /// The part an id stands for.
    pub fn from_id(id: u16) -> Segment {
        match id {
            BACKGROUND => Segment::Background,
            TABLE => Segment::Table,
            _ if id < FIRST_OBJECT => Segment::Bin((id - FIRST_BIN) as usize),
            _ if id < FIRST_LINK => Segment::Object((id - FIRST_OBJECT) as usize),
            _ => Segment::Link((id - FIRST_LINK) as usize),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_round_trip_and_overflow_is_an_error() {
        for s in [
            Segment::Background,
            Segment::Table,
            Segment::Bin(0),
            Segment::Bin(29),
            Segment::Object(0),
            Segment::Object(31),
            Segment::Link(0),
            Segment::Link(11),
        ] {
            assert_eq!(Segment::from_id(s.id().unwrap()), s);
        }
        assert!(Segment::Bin(30).id().is_err());
        assert!(Segment::Object(32).id().is_err());
    }
}
