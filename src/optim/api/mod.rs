//! What the optimizer offers outside its iteration: `DiffRender` (render, backward and a
//! step for the caller's own loss), the problem an optimizer is made from, the export of
//! the textures, the uncertainty maps and the measurements the bench and the job take.

pub(in crate::optim) mod diff_render;
pub(in crate::optim) mod outward;
pub(in crate::optim) mod problem;
pub mod texture_export;
pub mod uncertainty;
