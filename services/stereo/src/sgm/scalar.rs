//! Portable kernels: the same integers as the AVX2 ones, lane by lane.

use super::*;

/// One path step over all `dpad` lanes: `out = C + min(prev, prev±1 + P1, mprev + P2) - mprev`
/// in saturating u8 arithmetic (lanes past the ends see 255 as their neighbour). Returns
/// the minimum of `out`. (Written as branch-free slice loops so that the compiler
/// vectorises them with the baseline SSE2.)
#[inline]
pub(super) fn step(prev: &[u8], mprev: u8, cost: &[u8], pen: Penalties, out: &mut [u8]) -> u8 {
    let n = prev.len();
    let cap = mprev.saturating_add(pen.p2);
    let lane = |lm: u8, l0: u8, lp: u8, c: u8| {
        let t = lm.min(lp).saturating_add(pen.p1).min(l0).min(cap);
        c.saturating_add(t).saturating_sub(mprev)
    };
    // n is a multiple of 32.
    out[0] = lane(u8::MAX, prev[0], prev[1], cost[0]);
    out[n - 1] = lane(prev[n - 2], prev[n - 1], u8::MAX, cost[n - 1]);
    for (o, (t, &c)) in out[1..n - 1]
        .iter_mut()
        .zip(prev.windows(3).zip(&cost[1..n - 1]))
    {
        *o = lane(t[0], t[1], t[2], c);
    }
    out.iter().fold(u8::MAX, |m, &v| m.min(v))
}

/// Raw costs of one row (`width * dpad`): Hamming distances for the disparities that
/// exist, [`CMAX`] otherwise (and for every lane of the pixels left of `min_disp`).
pub(super) fn raw_costs(geo: &Geometry, cl: &[u32], cr: &[u32], out: &mut [u8]) {
    let dpad = geo.dpad;
    out[..geo.dmin * dpad].fill(CMAX as u8);
    for x in geo.dmin..geo.width {
        let out = &mut out[x * dpad..(x + 1) * dpad];
        let nvalid = geo.nvalid(x);
        let c = cl[x];
        // Lane i compares with right pixel x - dmin - i: the right row read backwards.
        let right = &cr[x + 1 - geo.dmin - nvalid..=x - geo.dmin];
        for (o, &r) in out[..nvalid].iter_mut().zip(right.iter().rev()) {
            *o = crate::census::hamming(c, r) as u8;
        }
        out[nvalid..].fill(CMAX as u8);
    }
}

/// One row (costs in `b.cost`): ← (right to left), then →, ↓ and the diagonals (left to right),
/// S, and the winners or the volume.
pub(super) fn row(cfg: &RowCfg<'_>, b: &mut RowBufs<'_>, tmp: &mut [Vec<u8>; 6], s16: &mut [u16]) {
    let geo = cfg.geo;
    let (w, dmin, dpad) = (geo.width, geo.dmin, geo.dpad);
    let [prev_h, cur, held, hold_next, lr, _] = tmp;
    // Right to left: ←.
    prev_h.fill(0);
    let mut mprev = 0u8;
    for x in (dmin..w).rev() {
        let c = &b.cost[x * dpad..(x + 1) * dpad];
        if cfg.horiz {
            let l = &mut b.lbuf[x * dpad..(x + 1) * dpad];
            mprev = step(prev_h, mprev, c, cfg.pen, l);
            prev_h.copy_from_slice(l);
        }
    }
    // Left to right.
    prev_h.fill(0);
    let mut mprev_h = 0u8;
    held.fill(0);
    let mut held_min = 0u8;
    let slot = |x: usize| GUARD + x * dpad; // slot index x (= pixel x - 1)
    for x in dmin..w {
        let s = x + 1;
        let c = &b.cost[x * dpad..(x + 1) * dpad];
        // ↓: in place.
        let m = step(
            &b.vbuf[0][slot(s)..slot(s) + dpad],
            b.vmin[0][s],
            c,
            cfg.pen,
            cur,
        );
        b.vbuf[0][slot(s)..slot(s) + dpad].copy_from_slice(cur);
        b.vmin[0][s] = m;
        // S groups (the AVX2 kernel adds pairs in saturating u8 first, then widens).
        if cfg.diag {
            // From x - 1: read slot s - 1, then store the held result of x - 1 there.
            let m1 = step(
                &b.vbuf[1][slot(s - 1)..slot(s - 1) + dpad],
                b.vmin[1][s - 1],
                c,
                cfg.pen,
                hold_next,
            );
            b.vbuf[1][slot(s - 1)..slot(s - 1) + dpad].copy_from_slice(held);
            b.vmin[1][s - 1] = held_min;
            held.copy_from_slice(hold_next);
            held_min = m1;
            // From x + 1: read slot s + 1, write slot s.
            let m2 = step(
                &b.vbuf[2][slot(s + 1)..slot(s + 1) + dpad],
                b.vmin[2][s + 1],
                c,
                cfg.pen,
                lr,
            );
            b.vbuf[2][slot(s)..slot(s) + dpad].copy_from_slice(lr);
            b.vmin[2][s] = m2;
        }
        if cfg.horiz {
            let mh = step(prev_h, mprev_h, c, cfg.pen, hold_next);
            prev_h.copy_from_slice(hold_next);
            mprev_h = mh;
        }
        // Sum in the same groups as the AVX2 kernel (pairs added in saturating u8 first).
        let s16 = &mut s16[..dpad];
        let left = &b.lbuf[x * dpad..(x + 1) * dpad];
        let pair = |a: &[u8], b: &[u8], s16: &mut [u16]| {
            for ((o, &u), &v) in s16.iter_mut().zip(a).zip(b) {
                *o += u.saturating_add(v) as u16;
            }
        };
        let single = |a: &[u8], s16: &mut [u16]| {
            for (o, &u) in s16.iter_mut().zip(a) {
                *o += u as u16;
            }
        };
        s16.fill(0);
        match (cfg.horiz, cfg.diag) {
            (true, true) => {
                pair(prev_h, held, s16);
                pair(cur, lr, s16);
                single(left, s16);
            }
            (true, false) => {
                pair(prev_h, cur, s16);
                single(left, s16);
            }
            (false, true) => {
                pair(cur, held, s16);
                single(lr, s16);
            }
            (false, false) => single(cur, s16),
        }
        match cfg.vol {
            Volume::Store => b.vol[x * dpad..(x + 1) * dpad].copy_from_slice(&s16[..dpad]),
            Volume::AddAndPick | Volume::None => {
                if cfg.vol == Volume::AddAndPick {
                    for (sv, &v) in s16.iter_mut().zip(&b.vol[x * dpad..(x + 1) * dpad]) {
                        *sv += v;
                    }
                }
                b.winners
                    .set(x, pick(&s16[..dpad], geo.nvalid(x), cfg.uniq));
            }
        }
    }
    if cfg.diag {
        let s = w + 1;
        b.vbuf[1][slot(s - 1)..slot(s - 1) + dpad].copy_from_slice(held);
        b.vmin[1][s - 1] = held_min;
    }
}

/// Winner-take-all over the first `nvalid` lanes of S, with the uniqueness test.
pub(super) fn pick(s: &[u16], nvalid: usize, uniq: u32) -> Winner {
    let s = &s[..nvalid];
    let min = |v: &[u16]| v.iter().fold(u16::MAX, |m, &x| m.min(x));
    let cost = min(s);
    // The lowest disparity with the lowest S.
    let best = s.iter().position(|&v| v == cost).unwrap_or(0);
    // Ambiguous when some S more than one disparity away satisfies
    // S * (100 - u) < best S * 100; the lowest such S decides.
    let far = min(&s[..best.saturating_sub(1)]).min(min(s.get(best + 2..).unwrap_or(&[])));
    let unique = uniq == 0 || far as u32 * (100 - uniq) >= cost as u32 * 100;
    Winner {
        best: best as u16,
        cost,
        below: if best > 0 { s[best - 1] } else { u16::MAX },
        above: if best + 1 < nvalid {
            s[best + 1]
        } else {
            u16::MAX
        },
        unique,
    }
}
