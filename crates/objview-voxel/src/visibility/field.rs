//! The Chebyshev distance field of S_gt's occupancy grid, which lets the walks leap over empty
//! space. Built once per [`super::InverseCaster`]; its own module because it is a self-contained
//! bitmap algorithm (tested against brute force).

use crate::set::VoxelSet;

/// Distance-field cap: cells farther than this from S_gt store `FIELD_CAP + 1`.
pub(super) const FIELD_CAP: u8 = 30;

/// Chebyshev (L∞) distance transform of the set's occupancy grid, capped: repeated one-cell
/// dilations of the bitmap (shift-OR along z inside each row, OR of neighbouring rows along y
/// and x), recording the level at which each cell is first reached.
pub(super) fn distance_field(set: &VoxelSet) -> Vec<u8> {
    let [nx, ny, nz] = set.grid_dims();
    let mut field = vec![FIELD_CAP + 1; nx * ny * nz];
    if set.is_empty() {
        return field;
    }
    let rw = set.row_words();
    let rows = nx * ny;
    // Valid-bit mask of the last word of a row.
    let tail = nz - (rw - 1) * 64;
    let last_mask = if tail == 64 { u64::MAX } else { (1u64 << tail) - 1 };
    let mut cur: Vec<u64> = set.bitmap().to_vec();
    let write_new = |field: &mut [u8], new: &[u64], level: u8| {
        for (wi, &w) in new.iter().enumerate() {
            let mut w = w;
            while w != 0 {
                let bit = wi * 64 + w.trailing_zeros() as usize;
                w &= w - 1;
                let (row, z) = (bit / (rw * 64), bit % (rw * 64));
                field[row * nz + z] = level;
            }
        }
    };
    write_new(&mut field, &cur, 0);
    let mut tmp = vec![0u64; cur.len()];
    let mut next = vec![0u64; cur.len()];
    for level in 1..=FIELD_CAP {
        // z: shift-OR inside each row, carrying across words.
        for row in 0..rows {
            let s = &cur[row * rw..(row + 1) * rw];
            for i in 0..rw {
                let mut w = s[i] | (s[i] << 1) | (s[i] >> 1);
                if i > 0 {
                    w |= s[i - 1] >> 63;
                }
                if i + 1 < rw {
                    w |= s[i + 1] << 63;
                }
                if i + 1 == rw {
                    w &= last_mask;
                }
                tmp[row * rw + i] = w;
            }
        }
        // y: OR of rows y−1, y, y+1 (same x).
        for x in 0..nx {
            for y in 0..ny {
                let base = (x * ny + y) * rw;
                for i in 0..rw {
                    let mut w = tmp[base + i];
                    if y > 0 {
                        w |= tmp[base - rw + i];
                    }
                    if y + 1 < ny {
                        w |= tmp[base + rw + i];
                    }
                    next[base + i] = w;
                }
            }
        }
        // x: OR of planes x−1, x, x+1.
        let plane = ny * rw;
        for x in 0..nx {
            for j in 0..plane {
                let mut w = next[x * plane + j];
                if x > 0 {
                    w |= next[(x - 1) * plane + j];
                }
                if x + 1 < nx {
                    w |= next[(x + 1) * plane + j];
                }
                tmp[x * plane + j] = w;
            }
        }
        // tmp = dilated; new cells = tmp & !cur.
        let mut any_new = false;
        for (n, (&d, &c)) in next.iter_mut().zip(tmp.iter().zip(&cur)) {
            *n = d & !c;
            any_new |= *n != 0;
        }
        if !any_new {
            break;
        }
        write_new(&mut field, &next, level);
        std::mem::swap(&mut cur, &mut tmp);
    }
    field
}
