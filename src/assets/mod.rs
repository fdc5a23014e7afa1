//! Writing glTF assets: a glTF/GLB writer (`authoring`, also used for `optimized.glb` and by
//! the tests) and the generators of the bundled scenes (`bundled`: `scenes/default`;
//! `bench_scenes`, with the indirect-lit scenes in `bench_scenes/room.rs`: `scenes/bench`), run as `psrestir make-scenes`, and of the
//! scene family with its train and test splits (`family`: `make-scenes --family`). Reading scenes is
//! `crate::scene`'s job.

pub mod authoring;
pub mod bench_scenes;
pub mod bundled;
pub mod family;
