//! A network's first layer — a 3×3, stride-2, zero-padded convolution of the one-channel input
//! followed by a ReLU — computed here instead of by tract (`net.rs` finds the layer in the graph,
//! takes its weights from it and gives tract the rest).
//!
//! Why: tract lowers every convolution to a matrix product over a lazily gathered im2col matrix;
//! with one input channel that matrix has nine rows and the gathering, not the arithmetic, is the
//! cost — 36 µs of level 1's 155 µs for 1.6 % of its multiply-adds (`core/examples/profile_net.rs`),
//! plus two explicit `Pad` passes (of the input, and of the first layer's output for the second
//! layer). Here the input rows are split into even and odd columns so every tap is a contiguous
//! run, the loops vectorise, and the output is written straight into the second layer's padded
//! input (its border stays zero), so tract's second convolution runs without padding.

/// The first layer of one network and its buffers. Shapes: input `batch × in_h × in_w` (what the
/// network's image input held), output `batch × channels × (out_h + 2·pad) × (out_w + 2·pad)`.
#[derive(Debug, Clone)]
pub(crate) struct Stem {
    batch: usize,
    channels: usize,
    in_h: usize,
    in_w: usize,
    out_h: usize,
    out_w: usize,
    /// Border of zeros around each output plane: the second layer's padding.
    pad: usize,
    /// Per channel: the 3×3 kernel row by row, then the bias.
    weights: Vec<[f32; 10]>,
    /// The network input as the caller filled it.
    input: Vec<f32>,
    /// The zero-padded input's `in_h + 2` rows split into even and odd columns, each row
    /// `out_w` rounded up to [`LANES`], plus one, long.
    even: Vec<f32>,
    odd: Vec<f32>,
}

impl Stem {
    /// A stem for a `batch × 1 × in_h × in_w` input with the weights `kernel` (`channels × 9`, row
    /// by row) and `bias` (`channels`), writing planes with a zero border of `pad`.
    pub(crate) fn new(
        batch: usize,
        in_h: usize,
        in_w: usize,
        kernel: &[f32],
        bias: &[f32],
        pad: usize,
    ) -> Self {
        let channels = bias.len();
        debug_assert_eq!(kernel.len(), 9 * channels);
        // ONNX output size of a 3×3 kernel, stride 2, padding 1: ⌊(n + 2 − 3) / 2⌋ + 1.
        let (out_h, out_w) = (in_h.div_ceil(2), in_w.div_ceil(2));
        let weights = kernel
            .chunks_exact(9)
            .zip(bias)
            .map(|(k, &b)| std::array::from_fn(|i| if i < 9 { k[i] } else { b }))
            .collect();
        Self {
            batch,
            channels,
            in_h,
            in_w,
            out_h,
            out_w,
            pad,
            weights,
            input: vec![0.0; batch * in_h * in_w],
            even: vec![0.0; (in_h + 2) * (out_w.next_multiple_of(LANES) + 1)],
            odd: vec![0.0; (in_h + 2) * (out_w.next_multiple_of(LANES) + 1)],
        }
    }

    /// The shape of the output: the second layer's input.
    pub(crate) fn output_shape(&self) -> [usize; 4] {
        let p = 2 * self.pad;
        [self.batch, self.channels, self.out_h + p, self.out_w + p]
    }

    /// The network input, `batch × in_h × in_w`, for the caller to fill.
    pub(crate) fn input_mut(&mut self) -> &mut [f32] {
        &mut self.input
    }

    crate::cpu::with_avx2_copy! {
        /// Computes the layer on the current input into the interior of `out` (of
        /// [`Self::output_shape`]; its border is left as it is, zero).
        pub(crate) fn run / run_avx2 (&mut self, out: &mut [f32]) => run_body
    }

    #[inline(always)]
    fn run_body(&mut self, out: &mut [f32]) {
        let (h, w, oh, ow, p) = (self.in_h, self.in_w, self.out_h, self.out_w, self.pad);
        let (pw, plane) = (ow + 2 * p, (oh + 2 * p) * (ow + 2 * p));
        let ew = ow.next_multiple_of(LANES) + 1;
        let (even, odd) = (&mut self.even, &mut self.odd);
        for (b, image) in self.input.chunks_exact(h * w).enumerate() {
            // Padded row r (image row r − 1) into its even and odd columns: padded column 2j is
            // image column 2j − 1, padded column 2j + 1 is image column 2j. Zeros elsewhere: the
            // padding, and the lanes past the row's end.
            even.fill(0.0);
            odd.fill(0.0);
            for (r, src) in image.chunks_exact(w).enumerate() {
                let (e, o) = (
                    &mut even[(r + 1) * ew..][..ew],
                    &mut odd[(r + 1) * ew..][..ew],
                );
                for (d, &v) in e[1..].iter_mut().zip(src.iter().skip(1).step_by(2)) {
                    *d = v;
                }
                for (d, &v) in o.iter_mut().zip(src.iter().step_by(2)) {
                    *d = v;
                }
            }
            let out_b = &mut out[b * self.channels * plane..][..self.channels * plane];
            for y in 0..oh {
                for x0 in (0..ow).step_by(LANES) {
                    // The nine taps of LANES outputs, loaded once for every channel.
                    let taps: [[f32; LANES]; 9] = std::array::from_fn(|k| {
                        let (dy, dx) = (k / 3, k % 3);
                        let row = (2 * y + dy) * ew;
                        let (src, at) = match dx {
                            0 => (&*even, row + x0),
                            1 => (&*odd, row + x0),
                            _ => (&*even, row + x0 + 1),
                        };
                        std::array::from_fn(|l| src[at + l])
                    });
                    let n = LANES.min(ow - x0);
                    for (wt, dst) in self.weights.iter().zip(out_b.chunks_exact_mut(plane)) {
                        let mut acc = [wt[9]; LANES];
                        for (k, tap) in taps.iter().enumerate() {
                            for (a, &t) in acc.iter_mut().zip(tap) {
                                *a += wt[k] * t;
                            }
                        }
                        let row = &mut dst[(y + p) * pw + p + x0..][..n];
                        for (d, &a) in row.iter_mut().zip(&acc) {
                            *d = a.max(0.0);
                        }
                    }
                }
            }
        }
    }
}

/// Outputs computed together: one AVX2 register of f32.
const LANES: usize = 8;

#[cfg(test)]
mod tests {
    use super::*;

    /// The layer by its definition: zero padding 1, stride 2, bias, ReLU.
    fn direct(
        input: &[f32],
        h: usize,
        w: usize,
        kernel: &[f32],
        bias: &[f32],
    ) -> Vec<Vec<Vec<f32>>> {
        let (oh, ow) = (h.div_ceil(2), w.div_ceil(2));
        let at = |y: isize, x: isize| {
            if y < 0 || x < 0 || y >= h as isize || x >= w as isize {
                0.0
            } else {
                f64::from(input[y as usize * w + x as usize])
            }
        };
        (0..bias.len())
            .map(|c| {
                (0..oh)
                    .map(|y| {
                        (0..ow)
                            .map(|x| {
                                let mut s = f64::from(bias[c]);
                                for dy in 0..3 {
                                    for dx in 0..3 {
                                        s += f64::from(kernel[9 * c + 3 * dy + dx])
                                            * at(
                                                2 * y as isize + dy as isize - 1,
                                                2 * x as isize + dx as isize - 1,
                                            );
                                    }
                                }
                                s.max(0.0) as f32
                            })
                            .collect()
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn matches_the_definition_with_a_zero_border() {
        // Even and odd sides, one and two batch slots, border 0 and 1.
        for &(batch, h, w, pad) in &[(1, 8, 10, 1), (2, 7, 5, 1), (1, 6, 6, 0), (2, 3, 4, 2)] {
            let channels = 3;
            let kernel: Vec<f32> = (0..9 * channels)
                .map(|i| ((i * 37 % 17) as f32 - 8.0) / 10.0)
                .collect();
            let bias = [0.1, -0.3, 0.0];
            let mut stem = Stem::new(batch, h, w, &kernel, &bias, pad);
            let images: Vec<f32> = (0..batch * h * w)
                .map(|i| (i * 53 % 29) as f32 / 29.0)
                .collect();
            stem.input_mut().copy_from_slice(&images);
            let [nb, nc, ph, pw] = stem.output_shape();
            assert_eq!([nb, nc], [batch, channels]);
            // A sentinel border shows any write outside the interior.
            let mut out = vec![7.0; nb * nc * ph * pw];
            stem.run(&mut out);
            let (oh, ow) = (ph - 2 * pad, pw - 2 * pad);
            for b in 0..batch {
                let want = direct(&images[b * h * w..][..h * w], h, w, &kernel, &bias);
                for c in 0..channels {
                    let plane = &out[(b * nc + c) * ph * pw..][..ph * pw];
                    for y in 0..ph {
                        for x in 0..pw {
                            let got = plane[y * pw + x];
                            let inside =
                                (pad..pad + oh).contains(&y) && (pad..pad + ow).contains(&x);
                            if inside {
                                let v = want[c][y - pad][x - pad];
                                assert!(
                                    (got - v).abs() < 1e-5,
                                    "b{b} c{c} ({y},{x}): {got} vs {v}"
                                );
                            } else {
                                assert_eq!(got, 7.0, "border written at b{b} c{c} ({y},{x})");
                            }
                        }
                    }
                }
            }
        }
    }
}
