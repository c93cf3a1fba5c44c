//! The winner-take-all with two-sided uniqueness: the best hypothesis of every left pixel,
//! what every right pixel has granted, and the rivals of the ambiguity test.

/// Winner-take-all state of one left pixel.
#[derive(Debug, Clone, Copy)]
pub(super) struct LeftBest {
    /// Best goodness (0 = none yet).
    pub(super) g: f32,
    /// Best goodness among hypotheses more than 1 px from the best.
    pub(super) second: f32,
    /// Disparity of the best hypothesis, 1/256 px.
    pub(super) d: i32,
    /// Index of the best hypothesis.
    pub(super) h: u32,
}

/// What a right pixel has granted so far.
#[derive(Debug, Clone, Copy)]
pub(super) struct RightGrant {
    /// Goodness of the grant (0 = none).
    pub(super) g: f32,
    /// Its disparity, 1/256 px.
    pub(super) d: i32,
}

/// A disparity no hypothesis can have (far from every real one).
pub(super) const NO_DISP: i32 = i32::MIN / 4;

/// Winner-take-all state with two-sided uniqueness.
#[derive(Debug, Default)]
pub(super) struct Wta {
    pub(super) left: Vec<LeftBest>,
    pub(super) right: Vec<RightGrant>,
    /// Hypotheses further apart than this (1/256 px) are rivals in the ambiguity test.
    pub(super) rival_q8: i32,
}

impl Wta {
    /// Clears the state for `n` pixels; `max_stretch` is the largest stretch factor, which is
    /// also the spacing of neighbouring shifts in px.
    pub(super) fn reset(&mut self, n: usize, max_stretch: f32) {
        // Neighbouring shifts (spacing m px) are never rivals: more than m + 1/2 px apart.
        self.rival_q8 = (256.0 * (max_stretch.max(1.0) + 0.5)).round() as i32;
        let none = LeftBest {
            g: 0.0,
            second: 0.0,
            d: NO_DISP,
            h: u32::MAX,
        };
        self.left.clear();
        self.left.resize(n, none);
        self.right.clear();
        self.right.resize(n, RightGrant { g: 0.0, d: NO_DISP });
    }

    /// Left pixel `p` (index) may match right pixel `q` (index) with goodness `g` at disparity
    /// `d_q8` under hypothesis `h`: it takes it when `g` beats both its own best and the grant
    /// of `q`; every hypothesis far enough from the best (a rival) feeds the ambiguity test.
    #[inline(always)]
    pub(super) fn offer(&mut self, p: usize, q: usize, g: f32, d_q8: i32, h: u32) {
        let l = &mut self.left[p];
        let far = (d_q8 - l.d).abs() > self.rival_q8;
        if g > l.g {
            let r = &mut self.right[q];
            if g > r.g {
                let second = if far { l.second.max(l.g) } else { l.second };
                *l = LeftBest {
                    g,
                    second,
                    d: d_q8,
                    h,
                };
                *r = RightGrant { g, d: d_q8 };
                return;
            }
        }
        if far && g > l.second {
            l.second = g;
        }
    }
}
