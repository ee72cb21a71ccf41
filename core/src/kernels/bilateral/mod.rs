//! The bilateral filter's sums over a padded 8-bit image (`landmarks::filter::Bilateral`, which
//! computes the tables and the padding as OpenCV's `cv::bilateralFilter` does): each output pixel
//! is `Σ v·w / Σ w` over the taps of a disc, each tap's weight its spatial weight times the
//! colour weight of its difference to the centre, in float32, clamped and truncated to u8.
//!
//! | form | how |
//! |---|---|
//! | portable (the reference; aarch64, where the compiler vectorises it) | tap by tap over each output row |
//! | AVX2 + FMA (`x86_64.rs`) | eight pixels per register, the colour weights from one gather per tap |
//! | AVX-512F (`x86_64.rs`) | sixteen pixels per register, then eight, then single pixels |
//!
//! Every form adds each pixel's taps in OpenCV's order with the same operations (Rust never
//! contracts them into fused multiply-adds), so all write the same bytes: the tests hold each to
//! the per-pixel loop ([`Filter::pixel`]) byte for byte.

#[cfg(target_arch = "x86_64")]
mod x86_64;

use crate::kernels::cpu::PixelForm as Form;

/// One filtering: the padded image and the tables every form reads.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Filter<'a> {
    /// The image with `radius` pixels of border on every side: `height + 2·radius` rows of
    /// `width + 2·radius` bytes.
    pub(crate) padded: &'a [u8],
    /// The output's width.
    pub(crate) width: usize,
    /// The output's height.
    pub(crate) height: usize,
    /// The border's width: the disc's radius.
    pub(crate) radius: usize,
    /// Each tap as an offset in `padded` from the centre pixel, in the order the sums add them.
    pub(crate) offsets: &'a [isize],
    /// Each tap's spatial weight (`offsets`' order).
    pub(crate) space_weight: &'a [f32],
    /// The colour weight of each absolute difference of levels.
    pub(crate) color_weight: &'a [f32; 256],
}

/// The portable form's running sums of one output row, kept between calls for their
/// allocations.
#[derive(Debug, Clone, Default)]
pub(crate) struct RowSums {
    sum: Vec<f32>,
    wsum: Vec<f32>,
}

impl Filter<'_> {
    /// Filters into `dst` (row-major, `width·height` long), through the widest form this CPU
    /// runs; `sums` is the portable form's scratch.
    ///
    /// # Panics
    /// Where `padded` or `dst` is shorter than the sizes say, or a tap reaches outside `padded`.
    pub(crate) fn run(&self, sums: &mut RowSums, dst: &mut [u8]) {
        self.run_with(Form::for_this_cpu(), sums, dst);
    }

    fn run_with(&self, form: Form, sums: &mut RowSums, dst: &mut [u8]) {
        match form {
            Form::Portable => self.rows(sums, dst),
            #[cfg(target_arch = "x86_64")]
            Form::Avx2 => {
                #[allow(unsafe_code)]
                // SAFETY: the CPU has AVX2 and FMA, which this form is only chosen with
                // (`Form::for_this_cpu`, `Form::all`).
                unsafe {
                    x86_64::filter_avx2(self, dst)
                }
            }
            #[cfg(target_arch = "x86_64")]
            Form::Avx512 => {
                #[allow(unsafe_code)]
                // SAFETY: the CPU has AVX-512F, AVX2 and FMA, which this form is only chosen with
                // (`Form::for_this_cpu`, `Form::all`).
                unsafe {
                    x86_64::filter_avx512(self, dst)
                }
            }
        }
    }

    /// The portable form: tap by tap over each output row.
    fn rows(&self, sums: &mut RowSums, dst: &mut [u8]) {
        let (width, r) = (self.width, self.radius);
        let pw = width + 2 * r;
        let cw = self.color_weight;
        sums.sum.resize(width, 0.0);
        sums.wsum.resize(width, 0.0);
        for y in 0..self.height {
            // Tap by tap over the whole row: each pixel still sums its taps in OpenCV's order (so
            // the result is the same to the bit), but the pixels' sums are independent chains the
            // CPU overlaps, where one pixel's dependent additions would serialise.
            sums.sum.fill(0.0);
            sums.wsum.fill(0.0);
            let c0 = (y + r) * pw + r;
            let centre = &self.padded[c0..c0 + width];
            for (&o, &sw) in self.offsets.iter().zip(self.space_weight) {
                let start = (c0 as isize + o) as usize;
                let taps = &self.padded[start..start + width];
                for (((&v, &v0), sum), wsum) in taps
                    .iter()
                    .zip(centre)
                    .zip(sums.sum.iter_mut())
                    .zip(sums.wsum.iter_mut())
                {
                    let w = sw * cw[usize::from(v.abs_diff(v0))];
                    *wsum += w;
                    *sum += f32::from(v) * w;
                }
            }
            for ((d, &sum), &wsum) in dst[y * width..(y + 1) * width]
                .iter_mut()
                .zip(&sums.sum)
                .zip(&sums.wsum)
            {
                *d = quantize(sum, wsum);
            }
        }
    }

    /// One output pixel, centred at `c` in `padded`, in OpenCV's loop order: the definition the
    /// other forms reproduce to the bit (unit test), and the vector forms' row tail.
    #[cfg_attr(not(any(test, target_arch = "x86_64")), allow(dead_code))]
    fn pixel(&self, c: usize) -> u8 {
        let v0 = self.padded[c];
        let (mut sum, mut wsum) = (0f32, 0f32);
        for (&o, &sw) in self.offsets.iter().zip(self.space_weight) {
            let v = self.padded[(c as isize + o) as usize];
            let w = sw * self.color_weight[usize::from(v.abs_diff(v0))];
            wsum += w;
            sum += f32::from(v) * w;
        }
        quantize(sum, wsum)
    }
}

/// A pixel's weighted mean to u8. The OpenCV 5 build the training uses truncates here
/// (tests/data/m3_preproc holds its output: rounding instead puts far more pixels one level off).
#[inline(always)]
fn quantize(sum: f32, wsum: f32) -> u8 {
    (sum / wsum).clamp(0.0, 255.0) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    /// OpenCV's tables for a disc of `radius` and the sigmas 20 (colour) and 3 (space), the
    /// offsets for padded rows of `pw` bytes.
    fn tables(radius: isize, pw: usize) -> (Vec<isize>, Vec<f32>, [f32; 256]) {
        let (gc, gs) = ((-0.5 / (20.0f64 * 20.0)) as f32, (-0.5 / 9.0f64) as f32);
        let color: [f32; 256] = std::array::from_fn(|i| ((i * i) as f32 * gc).exp());
        let (mut offsets, mut space) = (Vec::new(), Vec::new());
        for dy in -radius..=radius {
            for dx in -radius..=radius {
                let dist = ((dy * dy + dx * dx) as f64).sqrt();
                if dist <= radius as f64 {
                    offsets.push(dy * pw as isize + dx);
                    space.push((dist * dist * f64::from(gs)).exp() as f32);
                }
            }
        }
        (offsets, space, color)
    }

    /// Every form this CPU runs against the per-pixel loop, to the bit: widths with and without
    /// tails of fewer than sixteen and eight pixels, discs of three radii.
    #[test]
    fn every_form_equals_the_per_pixel_loop_to_the_bit() {
        let mut state = 12345u32;
        let mut sums = RowSums::default();
        for radius in [1, 2, 3] {
            for (w, h) in [
                (64, 32),
                (48, 48),
                (40, 24),
                (7, 3),
                (1, 1),
                (13, 5),
                (21, 9),
                (40, 7),
                (17, 4),
                (25, 2),
            ] {
                let (pw, ph) = (w + 2 * radius, h + 2 * radius);
                let padded: Vec<u8> = (0..pw * ph)
                    .map(|i| {
                        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                        // Smooth ramps plus noise: many sums land near level boundaries.
                        ((i % pw) * 3 + (i / pw) * 2) as u8 ^ (state >> 29) as u8
                    })
                    .collect();
                let (offsets, space_weight, color_weight) = tables(radius as isize, pw);
                let filter = Filter {
                    padded: &padded,
                    width: w,
                    height: h,
                    radius,
                    offsets: &offsets,
                    space_weight: &space_weight,
                    color_weight: &color_weight,
                };
                let mut want = vec![0u8; w * h];
                for y in 0..h {
                    for x in 0..w {
                        want[y * w + x] = filter.pixel((y + radius) * pw + x + radius);
                    }
                }
                for form in Form::all() {
                    let mut got = vec![0xEE; w * h];
                    filter.run_with(form, &mut sums, &mut got);
                    assert_eq!(got, want, "{form:?}, radius {radius}, {w}x{h}");
                }
                let mut got = vec![0xEE; w * h];
                filter.run(&mut sums, &mut got);
                assert_eq!(got, want, "dispatched, radius {radius}, {w}x{h}");
            }
        }
    }
}
