//! Transcendental functions that give the same bits on every platform.
//!
//! `f64::sin`, `f32::exp` and the like call the platform's maths library (glibc, bionic, Apple's
//! libm), whose last bit differs between platforms and between CPUs of one platform (glibc picks
//! FMA forms at run time on x86-64). A recording made on a phone must replay bit for bit on a
//! desktop (`record`), and a result must not depend on which libm the app links: so core computes
//! them with the `libm` crate, pure Rust built only from correctly rounded IEEE operations.
//! `core/clippy.toml` refuses the platform's functions in core.

/// The platform-independent forms of the `f32` / `f64` methods of the same name less the `m`:
/// `x.msin()` is `x.sin()` with the same bits everywhere.
pub trait Libm: Copy {
    /// Sine.
    fn msin(self) -> Self;
    /// Cosine.
    fn mcos(self) -> Self;
    /// Sine and cosine.
    fn msin_cos(self) -> (Self, Self);
    /// Tangent.
    fn mtan(self) -> Self;
    /// Arcsine.
    fn masin(self) -> Self;
    /// Arccosine.
    fn macos(self) -> Self;
    /// Arctangent.
    fn matan(self) -> Self;
    /// Four-quadrant arctangent of `self` (y) and `x`.
    fn matan2(self, x: Self) -> Self;
    /// e to the power `self`.
    fn mexp(self) -> Self;
    /// Natural logarithm.
    fn mln(self) -> Self;
    /// Base-10 logarithm.
    fn mlog10(self) -> Self;
    /// Base-2 logarithm.
    fn mlog2(self) -> Self;
    /// `self` to the power `e`.
    fn mpowf(self, e: Self) -> Self;
    /// √(self² + y²) without overflow.
    fn mhypot(self, y: Self) -> Self;
    /// Hyperbolic tangent.
    fn mtanh(self) -> Self;
    /// Cube root.
    fn mcbrt(self) -> Self;
}

/// Implements [`Libm`] for one float type from the `libm` functions of that type, named in the
/// trait's order.
macro_rules! libm_forms {
    ($t:ty: $sin:ident $cos:ident $sin_cos:ident $tan:ident $asin:ident $acos:ident $atan:ident
     $atan2:ident $exp:ident $ln:ident $log10:ident $log2:ident $powf:ident $hypot:ident
     $tanh:ident $cbrt:ident) => {
        impl Libm for $t {
            fn msin(self) -> Self {
                libm::$sin(self)
            }
            fn mcos(self) -> Self {
                libm::$cos(self)
            }
            fn msin_cos(self) -> (Self, Self) {
                libm::$sin_cos(self)
            }
            fn mtan(self) -> Self {
                libm::$tan(self)
            }
            fn masin(self) -> Self {
                libm::$asin(self)
            }
            fn macos(self) -> Self {
                libm::$acos(self)
            }
            fn matan(self) -> Self {
                libm::$atan(self)
            }
            fn matan2(self, x: Self) -> Self {
                libm::$atan2(self, x)
            }
            fn mexp(self) -> Self {
                libm::$exp(self)
            }
            fn mln(self) -> Self {
                libm::$ln(self)
            }
            fn mlog10(self) -> Self {
                libm::$log10(self)
            }
            fn mlog2(self) -> Self {
                libm::$log2(self)
            }
            fn mpowf(self, e: Self) -> Self {
                libm::$powf(self, e)
            }
            fn mhypot(self, y: Self) -> Self {
                libm::$hypot(self, y)
            }
            fn mtanh(self) -> Self {
                libm::$tanh(self)
            }
            fn mcbrt(self) -> Self {
                libm::$cbrt(self)
            }
        }
    };
}

libm_forms!(f64: sin cos sincos tan asin acos atan atan2 exp log log10 log2 pow hypot tanh cbrt);
libm_forms!(f32: sinf cosf sincosf tanf asinf acosf atanf atan2f expf logf log10f log2f powf hypotf tanhf cbrtf);

/// The angle between two vectors, radians: nalgebra's `angle` takes the platform's `acos`.
pub fn angle(a: &nalgebra::Vector3<f64>, b: &nalgebra::Vector3<f64>) -> f64 {
    a.cross(b).norm().matan2(a.dot(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Spot values against the platform's functions: the same functions, within an ulp or two.
    #[test]
    fn agrees_with_the_platform_within_ulps() {
        #[allow(clippy::disallowed_methods)]
        for x in [-3.0f64, -0.7, 0.1, 0.5, 1.3, 2.9] {
            let close = |a: f64, b: f64| (a - b).abs() <= 4.0 * f64::EPSILON * b.abs().max(1.0);
            assert!(close(x.msin(), x.sin()));
            assert!(close(x.mcos(), x.cos()));
            assert!(close(x.matan2(0.4), x.atan2(0.4)));
            assert!(close(x.mexp(), x.exp()));
            assert!(close(x.abs().mln(), x.abs().ln()));
            assert!(close(x.mhypot(0.3), x.hypot(0.3)));
            let y = x as f32;
            let closef = |a: f32, b: f32| (a - b).abs() <= 4.0 * f32::EPSILON * b.abs().max(1.0);
            assert!(closef(y.mexp(), y.exp()));
            assert!(closef(y.msin(), y.sin()));
        }
        let a = nalgebra::Vector3::new(1.0, 0.0, 0.0);
        let b = nalgebra::Vector3::new(1.0, 1.0, 0.0);
        assert!((angle(&a, &b) - std::f64::consts::FRAC_PI_4).abs() < 1e-15);
    }
}
