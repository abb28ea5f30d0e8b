//! Phase 2 of the loop, the paper's "rasterization": per surviving
//! triangle, three plane masks ANDed and ORed into the visibility mask,
//! whole mask rows per SIMD lane.

use super::simd::prefetch;
use crate::mask::{Mask, MaskRow};
use crate::raster::PlaneLut;

/// How many survivors ahead the lookup prefetches plane masks: the table
/// (3 MB at 128²) lives in L3, and a survivor's three masks are six cache
/// lines at random places; fetching them early overlaps their latency with
/// the ANDs and ORs of the survivors before. Eight survivors (48 lines) ahead
/// was best on the 2-core AMD EPYC (AVX-512): its look-ups took 10–15%
/// longer 16 ahead (more lines asked for than the core tracks at once) and
/// 4 or 12 ahead, on the human with and without potentially visible sets.
const AHEAD: usize = 8;

/// Per surviving triangle (three plane codes in `survivors`), ANDs its
/// three plane masks and ORs the result into `mask`. A plane mask is a stored mask, mirrored top to
/// bottom (with folded rows, by reading the two halves of storage
/// swapped) and complemented within the disk as its [`row_code`](crate::raster::row_code) says
/// (see [`PlaneLut`]). The complement is taken against all ones here,
/// which also sets the pixels outside the disk, so the mask is clipped to
/// the disk once at the end rather than per triangle.
#[inline(always)]
pub(super) fn lookup<W: MaskRow>(lut: &PlaneLut<W>, survivors: &[u32], mask: &mut Mask<W>) {
    let half = W::RESOLUTION / 2;
    let rows = lut.rows();
    let mut acc = W::EMPTY_ROWS;
    let (top, bottom) = acc.as_mut().split_at_mut(half);
    for (n, s) in survivors.chunks_exact(3).enumerate() {
        if let Some(ahead) = survivors.get(3 * (n + AHEAD)..3 * (n + AHEAD) + 3) {
            for &code in ahead {
                let start = (code >> 1) as usize & !(W::RESOLUTION - 1);
                prefetch(&rows[start..start + W::RESOLUTION]);
            }
        }
        let plane = |k: usize| {
            let code = s[k];
            let top = (code >> 1) as usize;
            let bottom = top ^ half;
            let flip = if code & 1 != 0 { !W::ZERO } else { W::ZERO };
            (&rows[top..top + half], &rows[bottom..bottom + half], flip)
        };
        let ((a0, a1, fa), (b0, b1, fb), (c0, c1, fc)) = (plane(0), plane(1), plane(2));
        for i in 0..half {
            top[i] = top[i] | ((a0[i] ^ fa) & (b0[i] ^ fb) & (c0[i] ^ fc));
            bottom[i] = bottom[i] | ((a1[i] ^ fa) & (b1[i] ^ fb) & (c1[i] ^ fc));
        }
    }
    let disk = lut.disk().rows();
    for (out, (&a, &d)) in mask
        .rows_mut()
        .iter_mut()
        .zip(acc.as_ref().iter().zip(disk))
    {
        *out = a & d;
    }
}
