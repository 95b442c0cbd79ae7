//! Hooks an episode runs with besides its own: a live view wraps the episode's hook
//! ([`WrapHook`]). Every hook only watches: it must not change an episode.

use std::sync::Arc;

use crate::runner::StepHook;

/// A hook to run each episode with, made per episode around the episode's own hook: a live
/// view (`kitchen-r eval --foxglove`) publishes through it. Like every hook it must not change
/// an episode (the runner leaves its reported overhead out of the wall-clock budget).
#[derive(Clone)]
pub struct WrapHook(pub Arc<WrapFn>);

/// What a [`WrapHook`] calls: the episode's hook in, the hook to run the episode with out.
pub type WrapFn = dyn for<'a> Fn(&'a mut dyn StepHook) -> Box<dyn StepHook + 'a> + Send + Sync;

impl WrapHook {
    /// `run` with `hook`, wrapped in `watch` when there is one: how `eval` and the workers run
    /// an episode that may be watched live.
    pub fn around<T>(
        watch: Option<&WrapHook>,
        hook: &mut dyn StepHook,
        run: impl FnOnce(&mut dyn StepHook) -> T,
    ) -> T {
        match watch {
            Some(w) => run((w.0)(hook).as_mut()),
            None => run(hook),
        }
    }
}

impl std::fmt::Debug for WrapHook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("WrapHook")
    }
}

impl PartialEq for WrapHook {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}
