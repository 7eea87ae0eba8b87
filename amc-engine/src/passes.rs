//! Makes the first passes of a run ([`PassPlan`], `amc_core::plan`) over an
//! input: each pass opens the input once and reads it from its start, only
//! as many frames as the pass takes.

use super::control::RunControl;
use super::RunError;
use amc_core::plan::{PassPlan, PlanChoices, Resolved};
use amc_core::Frame;
use amc_video::{self as video, InputOptions};
use std::path::Path;

/// Where the passes run: the render pool to push frames on (none: the
/// caller's thread) and the run's control, checked after every frame read.
#[derive(Clone, Copy, Default)]
pub(crate) struct On<'a> {
    pub pool: Option<&'a rayon::ThreadPool>,
    pub control: Option<&'a RunControl>,
}

impl On<'_> {
    fn install<T: Send>(&self, f: impl FnOnce() -> T + Send) -> T {
        match self.pool {
            Some(pool) => pool.install(f),
            None => f(),
        }
    }

    fn check(&self) -> Result<(), RunError> {
        self.control.map_or(Ok(()), RunControl::check)
    }
}

/// Plans `choices` (a plan that only estimates: the lens, the readout),
/// makes its passes on the caller's thread and returns what they resolved.
/// Frames are read in the input's own format (planar 4:2:0 for videos and
/// `.y4m`) whatever `opts` asks: the tracker reads its luma from them
/// without a colour conversion, as the run itself does from a video to a
/// video. (RGB frames cost a 720p `.y4m`'s `--fov auto` pass a conversion
/// and twice the memory of each of its 90 frames: about 0.1 s,
/// docs/speed.md.)
pub(crate) fn estimate(
    choices: PlanChoices,
    input: &Path,
    opts: &InputOptions,
) -> Result<Resolved, RunError> {
    let mut plan = PassPlan::new(choices)?;
    let opts = InputOptions {
        pixel_format: video::native_format(input),
        ..opts.clone()
    };
    make(&mut plan, input, &opts, On::default())?;
    Ok(plan.finish()?)
}

/// Makes every pass `plan` has left over `input` (opened with `opts`),
/// probing the frame size first where a field of view needs it. A pass that
/// reads no frame is [`RunError::NoFrames`].
pub(crate) fn make(
    plan: &mut PassPlan,
    input: &Path,
    opts: &InputOptions,
    on: On<'_>,
) -> Result<(), RunError> {
    if plan.needs_frame_size() {
        let (w, h) = video::frame_size(input, opts)?;
        plan.set_frame_size(w, h)?;
    }
    while plan.pass().is_some() {
        let mut src = video::open_input(input, opts)?;
        let info = src.info();
        let mut frame = Frame::new(info.width, info.height, opts.pixel_format);
        let mut read = 0usize;
        while !plan.is_full() {
            let Some(t) = src.next_frame(&mut frame)? else {
                break;
            };
            on.check()?;
            on.install(|| plan.push(frame.as_ref(), t))?;
            read += 1;
        }
        if read == 0 {
            return Err(RunError::NoFrames {
                path: input.to_path_buf(),
            });
        }
        on.install(|| plan.finish_pass())?;
        on.check()?;
    }
    Ok(())
}
