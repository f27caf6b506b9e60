//! What an executor shades a [`FramePlan`](super::FramePlan) into: the beauty alone, or
//! the compositing passes whose beauty is one of them.

use super::{ShadedFrame, ShadedPasses};

/// The outputs a frame is shaded into.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outputs {
    /// The beauty alone (`logsh shade`, `bench`, `sweep`).
    Beauty,
    /// The compositing passes and visibility terms (`logsh render`, and every frame with
    /// bounce light, whose gather reads the visibility).
    Passes,
}

/// A shaded frame, in the outputs asked for (one per frame, moved whole: the passes'
/// size is their vectors' headers).
#[allow(clippy::large_enum_variant)]
pub enum Shaded {
    Beauty(ShadedFrame),
    Passes(ShadedPasses),
}

impl Shaded {
    /// The beauty, taken out of the passes where those were shaded.
    pub fn into_beauty(self) -> ShadedFrame {
        match self {
            Shaded::Beauty(frame) => frame,
            Shaded::Passes(passes) => ShadedFrame { width: passes.width, height: passes.height, rgba: passes.beauty },
        }
    }

    /// The passes, `None` where only the beauty was shaded.
    pub fn into_passes(self) -> Option<ShadedPasses> {
        match self {
            Shaded::Beauty(_) => None,
            Shaded::Passes(passes) => Some(passes),
        }
    }
}
