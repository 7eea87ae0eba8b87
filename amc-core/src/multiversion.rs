//! `multiversion!`: one function body, compiled for the widest x86-64
//! instruction set the CPU has.
//!
//! The loops of a few hot functions (the tracker's evaluation, the metrics'
//! pass, the ghost-free merges) vectorize wider when compiled with AVX2 or
//! AVX-512 enabled, with no intrinsics in them: the same code, each result the
//! same bits (Rust never contracts to fused multiply-adds, and integer sums do
//! not depend on the order). `multiversion!` writes the dispatcher that picks
//! the variant at run time and the variants themselves, so that the body is
//! written once (as an `#[inline(always)]` method) and each instruction set is
//! one line.

/// Defines the method `$name`, which runs the method `$body` (the same
/// signature, `#[inline(always)]`) compiled for the first of the variants
/// this CPU has (`$variant: "features" if "detected feature"`, each one an
/// `unsafe` method compiled with those features, on x86-64 only), else as
/// compiled. The receiver is written `[&mut] self`, `[&] self` or `[] self`,
/// the bounds of its generic parameters `where [..]`.
///
/// ```text
/// multiversion! {
///     /// The frame's sums.
///     fn measure([&mut] self, frame: &FrameRef<'_>) -> FrameSums => measure_body {
///         measure_avx512: "avx512f,avx512bw" if "avx512bw",
///         measure_avx2: "avx2" if "avx2",
///     }
/// }
/// ```
macro_rules! multiversion {
    (
        $(#[$meta:meta])*
        $vis:vis fn $name:ident $(<$($gen:ident),*>)?
            ([$($recv:tt)*] $self:ident $(, $arg:ident: $ty:ty)* $(,)?) $(-> $ret:ty)?
        $(where [$($bound:tt)*])?
        => $body:ident { $($variant:ident: $features:literal if $detect:tt),+ $(,)? }
    ) => {
        multiversion!(@dispatcher [$(#[$meta])*] [$vis] $name [$(<$($gen),*>)?]
            [$($recv)* $self $(, $arg: $ty)*] $self ($($arg),*) [$(-> $ret)?]
            [$(where $($bound)*)?] $body { $($variant $detect)+ });
        multiversion!(@variants [$(<$($gen),*>)?] [$($recv)* $self $(, $arg: $ty)*] $self
            ($($arg),*) [$(-> $ret)?] [$(where $($bound)*)?] $body { $($variant $features)+ });
    };
    (@dispatcher [$($attr:tt)*] [$($vis:tt)*] $name:ident [$($gen:tt)*] [$($param:tt)*]
        $self:ident $args:tt [$($ret:tt)*] [$($where:tt)*] $body:ident
        { $($variant:ident $detect:tt)+ }
    ) => {
        $($attr)*
        $($vis)* fn $name $($gen)* ($($param)*) $($ret)* $($where)* {
            #[cfg(target_arch = "x86_64")]
            {
                $(
                    if std::arch::is_x86_feature_detected!($detect) {
                        // SAFETY: the CPU has the features the variant is
                        // compiled with (the one detected implies the others).
                        return unsafe { $self.$variant $args };
                    }
                )+
            }
            $self.$body $args
        }
    };
    (@variants [$($gen:tt)*] [$($param:tt)*] $self:ident $args:tt [$($ret:tt)*]
        [$($where:tt)*] $body:ident { }
    ) => {};
    (@variants [$($gen:tt)*] [$($param:tt)*] $self:ident $args:tt [$($ret:tt)*]
        [$($where:tt)*] $body:ident { $variant:ident $features:literal $($rest:tt)* }
    ) => {
        /// The body compiled with these target features (see `multiversion!`).
        ///
        /// # Safety
        /// The CPU must have them.
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = $features)]
        #[allow(clippy::too_many_arguments)]
        unsafe fn $variant $($gen)* ($($param)*) $($ret)* $($where)* {
            $self.$body $args
        }
        multiversion!(@variants [$($gen)*] [$($param)*] $self $args [$($ret)*] [$($where)*]
            $body { $($rest)* });
    };
}
