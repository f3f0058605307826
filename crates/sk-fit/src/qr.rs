//! The triangular factor of a tall matrix by a Householder QR in place, sequential (the
//! per-entry factorisations run on the rayon pool, one matrix per task), with a block
//! size chosen for the tall, narrow matrices of the SK and residue problems.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::qr::no_pivoting::factor::{qr_in_place, qr_in_place_scratch};
use faer::{Mat, MatMut, Par};

/// Block size of the blocked Householder QR: faer's default for these shapes
/// (`7920 x 38`: one block of all columns) runs at half the speed of blocks of 8 to 16
/// columns.
fn block_size(cols: usize) -> usize {
    cols.clamp(1, 16)
}

/// Householder QR of `a` (`rows x cols`) in place: on return the upper triangle of its
/// first `min(rows, cols)` rows holds `R`; the reflectors below the diagonal are left
/// there (callers read the upper triangle only).
pub(crate) fn r_in_place(a: MatMut<'_, f64>) {
    let k = a.nrows().min(a.ncols());
    if k == 0 {
        return;
    }
    let bs = block_size(k);
    let mut q = Mat::<f64>::zeros(bs, k);
    let mut buf = MemBuffer::new(qr_in_place_scratch::<f64>(
        a.nrows(),
        a.ncols(),
        bs,
        Par::Seq,
        Default::default(),
    ));
    qr_in_place(
        a,
        q.as_mut(),
        Par::Seq,
        MemStack::new(&mut buf),
        Default::default(),
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn r_reproduces_the_gram_matrix() {
        let (rows, cols) = (300, 37);
        let a = Mat::<f64>::from_fn(rows, cols, |i, j| {
            ((i * 31 + j * 17) % 23) as f64 / 7.0 + ((i + 1) as f64 * (j + 1) as f64).sin()
        });
        let mut f = a.clone();
        r_in_place(f.as_mut());
        let r = Mat::<f64>::from_fn(cols, cols, |i, j| if j >= i { f[(i, j)] } else { 0.0 });
        let g = a.transpose() * &a;
        let h = r.transpose() * &r;
        let scale = g.norm_max();
        assert!((&g - &h).norm_max() <= 1e-13 * scale);
    }
}
