//! The linear algebra shared by the trust-region backends: linearise every factor (whitened, robustly
//! reweighted by `sqrt(ρ'(s))`), build the normal equations, eliminate the marked variables (BA points)
//! by the Schur complement, and solve the damped reduced system
//!
//! ```text
//! (JᵀJ + D) δ = −Jᵀr,   D_ii = damping(H_ii)
//! ```
//!
//! with faer's dense Cholesky when the reduced system is small and faer's supernodal sparse Cholesky
//! (AMD ordering, symbolic analysis once per solve) otherwise. A backend builds one [`LinearSystem`]
//! per solve and calls [`LinearSystem::linearize`], [`LinearSystem::solve`] and the step helpers in
//! its own loop. A failed factorisation returns `None`, which a backend treats as a rejected step.

use std::collections::{BTreeSet, HashMap};

use nalgebra::{DMatrix, DVector};

use crate::{
    factor::FactorError,
    graph::Graph,
    optimizer::OptimError,
    values::{Key, Values},
};

/// Every factor's weighted, whitened linearisation, in flat buffers (one allocation per buffer per
/// linearisation, not several per factor).
#[derive(Default)]
struct Lins {
    /// Residuals of all factors, one after the other.
    r: Vec<f64>,
    /// Start of factor `i`'s residual in `r` (one more entry than factors).
    r_off: Vec<usize>,
    /// Jacobian blocks of all factors' keys, each column-major (`dim × tangent dim`).
    j: Vec<f64>,
    /// Start of each (factor, key) block in `j`, factor by factor, key by key (plus one final entry).
    j_off: Vec<usize>,
    /// Start of factor `i`'s keys in `j_off` (one more entry than factors).
    key_start: Vec<usize>,
}

impl Lins {
    fn with_capacity(factors: usize) -> Self {
        let mut l = Lins {
            r: Vec::with_capacity(factors * 2),
            r_off: Vec::with_capacity(factors + 1),
            j: Vec::new(),
            j_off: Vec::with_capacity(factors * 2 + 1),
            key_start: Vec::with_capacity(factors + 1),
        };
        l.r_off.push(0);
        l.key_start.push(0);
        l
    }

    /// Factor `i`'s residual.
    fn residual(&self, i: usize) -> &[f64] {
        &self.r[self.r_off[i]..self.r_off[i + 1]]
    }

    /// Factor `i`'s Jacobian block for its `t`-th key, as `(column-major slice, rows)`.
    fn jacobian(&self, i: usize, t: usize) -> (&[f64], usize) {
        let q = self.key_start[i] + t;
        (&self.j[self.j_off[q]..self.j_off[q + 1]], self.r_off[i + 1] - self.r_off[i])
    }
}

/// A column-major block as a nalgebra view.
fn view(j: &[f64], rows: usize) -> nalgebra::DMatrixView<'_, f64> {
    nalgebra::DMatrixView::from_slice(j, rows, j.len().checked_div(rows).unwrap_or(0))
}

/// Index of a free variable in the solve.
#[derive(Debug, Clone, Copy)]
enum Slot {
    Reduced { var: usize },
    Eliminated { var: usize },
}

struct Layout {
    /// Slot of each key (`None` for fixed or unused variables), indexed by `Key.0`.
    slots: Vec<Option<Slot>>,
    reduced: Vec<(Key, usize, usize)>, // key, offset, dim
    eliminated: Vec<(Key, usize)>,     // key, dim
    /// Per eliminated variable, where its `H_ee` (d_e², column-major) and `g_e` (d_e) start in
    /// [`Normal::hee`] and [`Normal::ge`].
    elim_off: Vec<(usize, usize)>,
    /// Links of eliminated variable `v`: `link_start[v]..link_start[v + 1]` index `link_var` (the
    /// reduced variables it shares a factor with, ascending) and `link_off` (where its block
    /// `C = J_eᵀ J_r`, d_e × d_r column-major, starts in [`Normal::c`]; one final entry).
    link_start: Vec<usize>,
    link_var: Vec<usize>,
    link_off: Vec<usize>,
    /// Per factor key (factor `i`'s keys start at `key_link_start[i]`): the link its Jacobian block
    /// adds to, or `usize::MAX` (no eliminated variable in the factor, or the key is not reduced).
    key_link_start: Vec<usize>,
    key_link: Vec<usize>,
}

/// Block pattern of the reduced system for the sparse path: which `(a, b)` blocks (`a ≥ b`) exist,
/// where their entries sit in the compressed-column lower triangle, and the symbolic factorisation.
struct Pattern {
    index: HashMap<(usize, usize), usize>,
    /// Block of each diagonal `(a, a)` (the common lookup, without hashing).
    diag_block: Vec<usize>,
    /// Per link pair of each eliminated variable, in the order the Schur complement visits them
    /// (variable by variable; link `a` ascending, then link `b ≤ a` ascending), the block it updates.
    schur_blocks: Vec<usize>,
    /// Per block, the CSC value position of each entry in column-major order (`usize::MAX` for the
    /// unused upper half of diagonal blocks).
    positions: Vec<Vec<usize>>,
    /// Per block, its `(a, b)`.
    pairs: Vec<(usize, usize)>,
    /// CSC value position of each scalar diagonal entry.
    diag: Vec<usize>,
    symbolic: faer::sparse::SymbolicSparseColMat<usize>,
    /// Symbolic Cholesky (AMD ordering, forced supernodal: the matrix is made of dense blocks).
    llt: faer::sparse::linalg::cholesky::SymbolicCholesky<usize>,
}

/// The compressed-column structure of the reduced system's lower triangle, block by block.
struct Csc {
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// Position of each scalar diagonal entry.
    diag: Vec<usize>,
    /// Per block, the position of each entry in column-major order (see [`Pattern::positions`]).
    positions: Vec<Vec<usize>>,
}

impl Pattern {
    /// The block pattern of the reduced system with its symbolic factorisation (`None` when the
    /// factorisation fails or a needed block is missing).
    fn build(layout: &Layout, graph: &Graph) -> Option<Self> {
        let pairs = block_pairs(layout, graph);
        let n: usize = layout.reduced.iter().map(|r| r.2).sum();
        let Csc { col_ptr, row_idx, diag, positions } = csc_structure(layout, &pairs, n);
        let symbolic = faer::sparse::SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        let llt = symbolic_cholesky(&symbolic)?;
        let index: HashMap<(usize, usize), usize> = pairs.iter().enumerate().map(|(i, p)| (*p, i)).collect();
        let diag_block = (0..layout.reduced.len()).map(|a| index.get(&(a, a)).copied()).collect::<Option<_>>()?;
        let schur_blocks = schur_blocks(layout, &index)?;
        Some(Self { index, diag_block, schur_blocks, positions, pairs, diag, symbolic, llt })
    }
}

/// The `(a, b)` blocks (`a ≥ b`) of the reduced system, ascending: the diagonal, the pairs of reduced
/// variables sharing a factor, and the pairs linked to a common eliminated variable (the Schur fill).
fn block_pairs(layout: &Layout, graph: &Graph) -> Vec<(usize, usize)> {
    let mut pairs: BTreeSet<(usize, usize)> = (0..layout.reduced.len()).map(|a| (a, a)).collect();
    let mut elim_links: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); layout.eliminated.len()];
    for e in graph.entries() {
        let mut red = Vec::new();
        let mut el = None;
        for k in e.factor.keys() {
            match layout.slots.get(k.0).copied().flatten() {
                Some(Slot::Reduced { var }) => red.push(var),
                Some(Slot::Eliminated { var }) => el = Some(var),
                None => {}
            }
        }
        for &a in &red {
            for &b in &red {
                if a >= b {
                    pairs.insert((a, b));
                }
            }
            if let Some(ev) = el {
                elim_links[ev].insert(a);
            }
        }
    }
    for links in &elim_links {
        for &a in links {
            for &b in links {
                if a >= b {
                    pairs.insert((a, b));
                }
            }
        }
    }
    pairs.into_iter().collect()
}

/// The compressed-column lower triangle (size `n`) of the blocks `pairs`: column by column, the
/// blocks of a column by ascending row variable.
fn csc_structure(layout: &Layout, pairs: &[(usize, usize)], n: usize) -> Csc {
    // blocks by column var, rows ascending
    let mut by_col: Vec<Vec<usize>> = vec![Vec::new(); layout.reduced.len()];
    for (i, &(_, b)) in pairs.iter().enumerate() {
        by_col[b].push(i);
    }
    for col in &mut by_col {
        col.sort_by_key(|&i| pairs[i].0);
    }
    let mut positions: Vec<Vec<usize>> =
        pairs.iter().map(|&(a, b)| vec![usize::MAX; layout.reduced[a].2 * layout.reduced[b].2]).collect();
    let mut col_ptr = Vec::with_capacity(n + 1);
    let mut row_idx = Vec::new();
    let mut diag = vec![0; n];
    col_ptr.push(0);
    for (b, col) in by_col.iter().enumerate() {
        let (_, rb, db) = layout.reduced[b];
        for j in 0..db {
            for &bi in col {
                let a = pairs[bi].0;
                let (_, ra, da) = layout.reduced[a];
                for i in 0..da {
                    if a == b && i < j {
                        continue;
                    }
                    if a == b && i == j {
                        diag[rb + j] = row_idx.len();
                    }
                    positions[bi][j * da + i] = row_idx.len();
                    row_idx.push(ra + i);
                }
            }
            col_ptr.push(row_idx.len());
        }
    }
    Csc { col_ptr, row_idx, diag, positions }
}

/// The symbolic Cholesky factorisation of the pattern (AMD ordering, supernodal), or `None` when faer
/// refuses it.
fn symbolic_cholesky(
    symbolic: &faer::sparse::SymbolicSparseColMat<usize>,
) -> Option<faer::sparse::linalg::cholesky::SymbolicCholesky<usize>> {
    use faer::sparse::linalg::{
        cholesky::{factorize_symbolic_cholesky, CholeskySymbolicParams, SymmetricOrdering},
        SupernodalThreshold,
    };
    factorize_symbolic_cholesky(
        symbolic.as_ref(),
        faer::Side::Lower,
        SymmetricOrdering::Amd,
        CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
            ..Default::default()
        },
    )
    .ok()
}

/// The block each link pair's Schur update goes to, in the order the elimination visits them (see
/// [`Pattern::schur_blocks`]); `None` when a pair has no block.
fn schur_blocks(layout: &Layout, index: &HashMap<(usize, usize), usize>) -> Option<Vec<usize>> {
    let mut schur_blocks = Vec::new();
    for ev in 0..layout.eliminated.len() {
        let links = &layout.link_var[layout.link_start[ev]..layout.link_start[ev + 1]];
        for (ai, &a) in links.iter().enumerate() {
            for &b in &links[..=ai] {
                schur_blocks.push(*index.get(&(a, b))?);
            }
        }
    }
    Some(schur_blocks)
}

/// Inverse of a damped eliminated block: fixed-size for points, dynamic otherwise.
enum HInv {
    Three(nalgebra::Matrix3<f64>),
    Dyn(DMatrix<f64>),
}

impl HInv {
    fn mul_vec(&self, x: &[f64]) -> Vec<f64> {
        match self {
            HInv::Three(h) => (h * nalgebra::Vector3::from_column_slice(x)).as_slice().to_vec(),
            HInv::Dyn(h) => (h * DVector::from_column_slice(x)).as_slice().to_vec(),
        }
    }

    /// `out` = row-major `H⁻¹ C` (d_e × n; `c` column-major).
    fn mul_mat_rowmajor(&self, cs: &[f64], n: usize, out: &mut Vec<f64>) {
        let de = cs.len().checked_div(n).unwrap_or(0);
        out.clear();
        out.resize(de * n, 0.0);
        match self {
            HInv::Three(h) => {
                for (i, col) in cs.chunks_exact(3).enumerate() {
                    let v = h * nalgebra::Vector3::new(col[0], col[1], col[2]);
                    out[i] = v.x;
                    out[n + i] = v.y;
                    out[2 * n + i] = v.z;
                }
            }
            HInv::Dyn(h) => {
                for (i, col) in cs.chunks_exact(de).enumerate() {
                    for k in 0..de {
                        out[k * n + i] = (0..de).map(|l| h[(k, l)] * col[l]).sum();
                    }
                }
            }
        }
    }
}

/// The reduced Hessian: dense (lower triangle used) or block-sparse following a [`Pattern`].
enum Reduced {
    Dense(DMatrix<f64>),
    Sparse(Vec<DMatrix<f64>>),
}

struct Normal {
    h: Reduced,
    g: DVector<f64>,
    /// `H_ee` blocks of the eliminated variables ([`Layout::elim_off`]).
    hee: Vec<f64>,
    /// Gradient blocks of the eliminated variables.
    ge: Vec<f64>,
    /// `C = J_eᵀ J_r` blocks of every link ([`Layout::link_off`]).
    c: Vec<f64>,
}

/// The problem's layout and (for the sparse path) the symbolic factorisation, built once per solve.
pub struct LinearSystem {
    layout: Layout,
    pattern: Option<Pattern>,
    n_red: usize,
}

/// A linearisation at one point: cost, per-factor whitened Jacobians and the normal equations.
pub struct Linearization {
    /// The cost `½ Σ ρ` at the point.
    pub cost: f64,
    lins: Lins,
    ne: Normal,
}

/// A step: the reduced variables' part (one vector) and one vector per eliminated variable.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Reduced (not eliminated) variables, in layout order.
    pub reduced: DVector<f64>,
    /// Eliminated variables, in layout order.
    pub eliminated: Vec<DVector<f64>>,
}

impl Step {
    /// Squared Euclidean norm.
    pub fn norm_squared(&self) -> f64 {
        self.reduced.norm_squared() + self.eliminated.iter().map(|d| d.norm_squared()).sum::<f64>()
    }

    /// Euclidean norm.
    pub fn norm(&self) -> f64 {
        self.norm_squared().sqrt()
    }

    /// `self · s`.
    pub fn scaled(&self, s: f64) -> Step {
        Step { reduced: &self.reduced * s, eliminated: self.eliminated.iter().map(|d| d * s).collect() }
    }

    /// `self + s · other` (same layout).
    pub fn add_scaled(&self, s: f64, other: &Step) -> Step {
        Step {
            reduced: &self.reduced + &other.reduced * s,
            eliminated: self.eliminated.iter().zip(&other.eliminated).map(|(a, b)| a + b * s).collect(),
        }
    }

    /// Dot product (same layout).
    pub fn dot(&self, other: &Step) -> f64 {
        self.reduced.dot(&other.reduced)
            + self.eliminated.iter().zip(&other.eliminated).map(|(a, b)| a.dot(b)).sum::<f64>()
    }
}

impl LinearSystem {
    /// Lay out the free variables of `graph` (fixed ones left out, marked ones eliminated) and, when the
    /// reduced system exceeds `dense_limit`, analyse its sparsity pattern.
    pub fn new(graph: &Graph, values: &Values, dense_limit: usize) -> Result<Self, OptimError> {
        let layout = layout(graph, values)?;
        let n_red: usize = layout.reduced.iter().map(|r| r.2).sum();
        let pattern =
            if n_red > dense_limit { Some(Pattern::build(&layout, graph).ok_or(OptimError::Symbolic)?) } else { None };
        Ok(Self { layout, pattern, n_red })
    }

    /// Size of the reduced system.
    pub fn reduced_dim(&self) -> usize {
        self.n_red
    }

    /// Whether the sparse Cholesky is used.
    pub fn is_sparse(&self) -> bool {
        self.pattern.is_some()
    }

    /// Whether any variable is free.
    pub fn has_free_variables(&self) -> bool {
        !(self.layout.reduced.is_empty() && self.layout.eliminated.is_empty())
    }

    /// The cost at `values`; `Err(i, e)` names the first factor that cannot be evaluated, and a
    /// non-finite robust cost counts as such.
    pub fn cost(&self, graph: &Graph, values: &Values) -> Result<f64, (usize, FactorError)> {
        linearize(graph, values, false).map(|(c, _)| c)
    }

    /// Linearise at `values` and build the normal equations.
    pub fn linearize(&self, graph: &Graph, values: &Values) -> Result<Linearization, (usize, FactorError)> {
        let (cost, lins) = linearize(graph, values, true)?;
        let ne = normal_equations(graph, &self.layout, &lins, self.pattern.as_ref());
        Ok(Linearization { cost, lins, ne })
    }

    /// Largest absolute gradient component.
    pub fn gradient_max(&self, lin: &Linearization) -> f64 {
        lin.ne.g.amax().max(lin.ne.ge.iter().fold(0.0, |m, x| m.max(x.abs())))
    }

    /// The gradient `Jᵀr` as a step.
    pub fn gradient(&self, lin: &Linearization) -> Step {
        let eliminated = (self.layout.eliminated.iter().zip(&self.layout.elim_off))
            .map(|(&(_, de), &(_, go))| DVector::from_column_slice(&lin.ne.ge[go..go + de]))
            .collect();
        Step { reduced: lin.ne.g.clone(), eliminated }
    }

    /// `½‖r‖² − ½‖r + J step‖²`, the decrease the linear model predicts (reweighted residuals).
    pub fn model_decrease(&self, graph: &Graph, lin: &Linearization, step: &Step) -> f64 {
        model_decrease(graph, &self.layout, &lin.lins, &step.reduced, &step.eliminated)
    }

    /// `‖J v‖²` (for the Cauchy point of a dog-leg).
    pub fn jacobian_norm_squared(&self, graph: &Graph, lin: &Linearization, v: &Step) -> f64 {
        // model_decrease(v) = −rᵀJv − ½‖Jv‖² and model_decrease(−v) = rᵀJv − ½‖Jv‖²: their sum is −‖Jv‖².
        let a = model_decrease(graph, &self.layout, &lin.lins, &v.reduced, &v.eliminated);
        let neg = v.scaled(-1.0);
        let b = model_decrease(graph, &self.layout, &lin.lins, &neg.reduced, &neg.eliminated);
        -(a + b)
    }

    /// `values ⊕ step`.
    pub fn retract(&self, values: &Values, step: &Step) -> Values {
        let mut trial = values.clone();
        for &(k, off, d) in &self.layout.reduced {
            if let Some(v) = values.get(k) {
                trial.set(k, v.retract(step.reduced.rows(off, d).as_slice()));
            }
        }
        for (&(k, _), de) in self.layout.eliminated.iter().zip(&step.eliminated) {
            if let Some(v) = values.get(k) {
                trial.set(k, v.retract(de.as_slice()));
            }
        }
        trial
    }

    /// Solve `(JᵀJ + D) δ = −Jᵀr` with `D_ii = damping(H_ii)` (the eliminated blocks damped the same
    /// way); `None` when a factorisation fails or the step is not finite.
    pub fn solve(&self, lin: &Linearization, damping: impl Fn(f64) -> f64) -> Option<Step> {
        damped_step(&self.layout, &lin.ne, damping, self.pattern.as_ref())
            .map(|(reduced, eliminated)| Step { reduced, eliminated })
    }
}

/// The layout of the solve: which variables are free, reduced or eliminated, where each sits, and the
/// links between eliminated and reduced variables.
fn layout(graph: &Graph, values: &Values) -> Result<Layout, OptimError> {
    let free = free_variables(graph, values)?;
    let mut layout = Layout::with_slots(graph, values, free);
    // Links between eliminated and reduced variables, fixed for the whole solve.
    let links = layout.links(graph);
    layout.set_link_offsets(&links);
    layout.set_key_links(graph);
    Ok(layout)
}

/// The keys that some factor moves (not fixed); an error when a factor's key has no value or a factor
/// has more than one eliminated variable.
fn free_variables(graph: &Graph, values: &Values) -> Result<BTreeSet<Key>, OptimError> {
    let mut free: BTreeSet<Key> = BTreeSet::new();
    for (i, e) in graph.entries().iter().enumerate() {
        let mut n_elim = 0;
        for &k in e.factor.keys() {
            if values.get(k).is_none() {
                return Err(OptimError::InitialEvaluation { factor: i, source: FactorError::WrongVariable(k) });
            }
            if graph.is_fixed(k) {
                continue;
            }
            if graph.is_eliminated(k) {
                n_elim += 1;
            }
            free.insert(k);
        }
        if n_elim > 1 {
            return Err(OptimError::Elimination { factor: i });
        }
    }
    Ok(free)
}

impl Layout {
    /// The slots of the free variables in key order (reduced ones with their offsets in the reduced
    /// system), without links yet.
    fn with_slots(graph: &Graph, values: &Values, free: BTreeSet<Key>) -> Self {
        let mut slots = vec![None; values.len()];
        let (mut reduced, mut eliminated) = (Vec::new(), Vec::new());
        let mut off = 0;
        for k in free {
            let dim = values.get(k).map(|v| v.dim()).unwrap_or(0);
            if graph.is_eliminated(k) {
                slots[k.0] = Some(Slot::Eliminated { var: eliminated.len() });
                eliminated.push((k, dim));
            } else {
                slots[k.0] = Some(Slot::Reduced { var: reduced.len() });
                reduced.push((k, off, dim));
                off += dim;
            }
        }
        Layout {
            slots,
            reduced,
            eliminated,
            elim_off: Vec::new(),
            link_start: Vec::new(),
            link_var: Vec::new(),
            link_off: Vec::new(),
            key_link_start: Vec::new(),
            key_link: Vec::new(),
        }
    }

    /// The eliminated variable among a factor's keys, if any.
    fn eliminated_var(&self, keys: &[Key]) -> Option<usize> {
        let mut el = None;
        for k in keys {
            if let Some(Slot::Eliminated { var }) = self.slots.get(k.0).copied().flatten() {
                el = Some(var);
            }
        }
        el
    }

    /// Per eliminated variable, the reduced variables it shares a factor with.
    fn links(&self, graph: &Graph) -> Vec<BTreeSet<usize>> {
        let mut links: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); self.eliminated.len()];
        for e in graph.entries() {
            if let Some(ev) = self.eliminated_var(e.factor.keys()) {
                for k in e.factor.keys() {
                    if let Some(Slot::Reduced { var }) = self.slots.get(k.0).copied().flatten() {
                        links[ev].insert(var);
                    }
                }
            }
        }
        links
    }

    /// Where each eliminated variable's `H_ee` and `g_e` start, and its links with where their `C`
    /// blocks start.
    fn set_link_offsets(&mut self, links: &[BTreeSet<usize>]) {
        let (mut link_start, mut link_var, mut link_off) = (vec![0], Vec::new(), vec![0]);
        let mut elim_off = Vec::with_capacity(self.eliminated.len());
        let (mut ho, mut go) = (0, 0);
        for (ev, set) in links.iter().enumerate() {
            let de = self.eliminated[ev].1;
            elim_off.push((ho, go));
            ho += de * de;
            go += de;
            for &a in set {
                link_var.push(a);
                let end = link_off.last().copied().unwrap_or(0) + de * self.reduced[a].2;
                link_off.push(end);
            }
            link_start.push(link_var.len());
        }
        (self.elim_off, self.link_start, self.link_var, self.link_off) = (elim_off, link_start, link_var, link_off);
    }

    /// The link each factor key's Jacobian block adds to (see [`Layout::key_link`]).
    fn set_key_links(&mut self, graph: &Graph) {
        let (mut key_link_start, mut key_link) = (Vec::with_capacity(graph.len() + 1), Vec::new());
        for e in graph.entries() {
            key_link_start.push(key_link.len());
            let el = self.eliminated_var(e.factor.keys());
            for k in e.factor.keys() {
                let l = match (el, self.slots.get(k.0).copied().flatten()) {
                    (Some(ev), Some(Slot::Reduced { var })) => {
                        let range = &self.link_var[self.link_start[ev]..self.link_start[ev + 1]];
                        range.binary_search(&var).map_or(usize::MAX, |p| self.link_start[ev] + p)
                    }
                    _ => usize::MAX,
                };
                key_link.push(l);
            }
        }
        key_link_start.push(key_link.len());
        (self.key_link_start, self.key_link) = (key_link_start, key_link);
    }
}

/// `C += Aᵀ B` for column-major `A` (r × da), `B` (r × db), `C` (da × db), each entry as
/// `dot(A_i, B_j) + C_ij` with the dot product summed in order: the same arithmetic as nalgebra's
/// `gemm_tr(1, A, B, 1)` (which it replaces on the hot path, without allocating), so the result is
/// bit-identical.
#[inline]
fn atb_add(c: &mut [f64], a: &[f64], b: &[f64], r: usize, da: usize, db: usize) {
    match r {
        2 => atb_add_r::<2>(c, a, b, da, db),
        3 => atb_add_r::<3>(c, a, b, da, db),
        4 => atb_add_r::<4>(c, a, b, da, db),
        _ => {
            // nalgebra sums long dot products in eight interleaved accumulators: defer to it.
            let mut m = nalgebra::DMatrixViewMut::from_slice(c, da, db);
            m.gemm_tr(1.0, &view(a, r), &view(b, r), 1.0);
        }
    }
}

#[inline(always)]
fn atb_add_r<const R: usize>(c: &mut [f64], a: &[f64], b: &[f64], da: usize, db: usize) {
    for (bj, cj) in b.chunks_exact(R).take(db).zip(c.chunks_exact_mut(da.max(1))) {
        for (ai, cij) in a.chunks_exact(R).take(da).zip(cj.iter_mut()) {
            let mut dot = 0.0;
            for k in 0..R {
                dot += ai[k] * bj[k];
            }
            *cij += dot;
        }
    }
}

fn linearize(graph: &Graph, values: &Values, jac: bool) -> Result<(f64, Lins), (usize, FactorError)> {
    let mut cost = 0.0;
    let mut lins = if jac { Lins::with_capacity(graph.entries().len()) } else { Lins::default() };
    let mut scratch = Vec::new();
    for (i, e) in graph.entries().iter().enumerate() {
        let dim = e.factor.dim();
        let keys = e.factor.keys();
        let r = if jac {
            let r0 = lins.r.len();
            lins.r.resize(r0 + dim, 0.0);
            lins.r_off.push(r0 + dim);
            let j0 = lins.j.len();
            let mut end = j0;
            for &k in keys {
                lins.j_off.push(end);
                end += dim * values.get(k).map_or(0, |v| v.dim());
            }
            lins.key_start.push(lins.j_off.len());
            lins.j.resize(end, 0.0);
            e.factor.evaluate_into(values, &mut lins.r[r0..], Some(&mut lins.j[j0..])).map_err(|err| (i, err))?;
            &mut lins.r[r0..]
        } else {
            scratch.clear();
            scratch.resize(dim, 0.0);
            e.factor.evaluate_into(values, &mut scratch, None).map_err(|err| (i, err))?;
            &mut scratch[..]
        };
        e.noise.whiten_slice(r);
        let s = nalgebra::DVectorView::from_slice(r, dim).norm_squared();
        let [rho, d1, _] = e.kernel.evaluate(s);
        if !rho.is_finite() {
            return Err((i, FactorError::Undefined("non-finite residual".into())));
        }
        cost += 0.5 * rho;
        if jac {
            let w = d1.max(0.0).sqrt();
            r.iter_mut().for_each(|x| *x *= w);
            let q0 = lins.key_start[i];
            for q in q0..q0 + keys.len() {
                let (b0, b1) = (lins.j_off[q], lins.j_off.get(q + 1).copied().unwrap_or(lins.j.len()));
                let block = &mut lins.j[b0..b1];
                e.noise.whiten_jacobian_slice(block, dim);
                block.iter_mut().for_each(|x| *x *= w);
            }
        }
    }
    if jac {
        lins.j_off.push(lins.j.len());
    }
    Ok((cost, lins))
}

/// The normal equations of a linearisation: the reduced Hessian and gradient, and for the eliminated
/// variables their `H_ee`, `g_e` and link blocks `C`, accumulated factor by factor.
fn normal_equations(graph: &Graph, layout: &Layout, lins: &Lins, pattern: Option<&Pattern>) -> Normal {
    let mut ne = Normal::zeros(layout, pattern);
    // (reduced var, column-major Jacobian block with the residual's rows)
    let mut red: Vec<(usize, &[f64])> = Vec::new();
    let mut rowmajor: Vec<Vec<f64>> = Vec::new();
    for (i, e) in graph.entries().iter().enumerate() {
        red.clear();
        let r = lins.residual(i);
        let rdim = r.len();
        let mut el: Option<(usize, &[f64])> = None;
        for (t, k) in e.factor.keys().iter().enumerate() {
            let (js, _) = lins.jacobian(i, t);
            match layout.slots.get(k.0).copied().flatten() {
                Some(Slot::Reduced { var }) => red.push((var, js)),
                Some(Slot::Eliminated { var }) => el = Some((var, js)),
                None => {}
            }
        }
        while rowmajor.len() < red.len() {
            rowmajor.push(Vec::new());
        }
        for (ai, &(_, ja)) in red.iter().enumerate() {
            transpose_into(ja, rdim, &mut rowmajor[ai]);
        }
        ne.add_reduced(layout, pattern, &red, &rowmajor, r);
        if let Some(el) = el {
            ne.add_eliminated(layout, lins, i, el, r);
        }
    }
    ne
}

impl Normal {
    /// Zero normal equations shaped by the layout (and, on the sparse path, by the block pattern).
    fn zeros(layout: &Layout, pattern: Option<&Pattern>) -> Self {
        let n_red: usize = layout.reduced.iter().map(|r| r.2).sum();
        let h = match pattern {
            None => Reduced::Dense(DMatrix::zeros(n_red, n_red)),
            Some(p) => Reduced::Sparse(
                p.pairs.iter().map(|&(a, b)| DMatrix::zeros(layout.reduced[a].2, layout.reduced[b].2)).collect(),
            ),
        };
        let g = DVector::zeros(n_red);
        let n_hee: usize = layout.eliminated.iter().map(|&(_, d)| d * d).sum();
        let n_ge: usize = layout.eliminated.iter().map(|&(_, d)| d).sum();
        let (hee, ge) = (vec![0.0; n_hee], vec![0.0; n_ge]);
        let c = vec![0.0; layout.link_off.last().copied().unwrap_or(0)];
        Normal { h, g, hee, ge, c }
    }

    /// Adds one factor's part to the reduced gradient and Hessian: `red` are its reduced variables
    /// with their Jacobian blocks, `rowmajor` the same blocks transposed, `r` its residual.
    fn add_reduced(
        &mut self,
        layout: &Layout,
        pattern: Option<&Pattern>,
        red: &[(usize, &[f64])],
        rowmajor: &[Vec<f64>],
        r: &[f64],
    ) {
        let (n_red, rdim) = (self.g.len(), r.len());
        let rv = nalgebra::DVectorView::from_slice(r, rdim);
        for ai in 0..red.len() {
            let (a, ja) = red[ai];
            let (_, ra, da) = layout.reduced[a];
            self.g.rows_mut(ra, da).gemv_tr(1.0, &view(ja, rdim), &rv, 1.0);
            for (bi, &(b, jb)) in red[..=ai].iter().enumerate() {
                // H_rc += J_rᵀ J_c with r ≥ c
                let (row, col, tr, jc) = if a >= b { (a, b, ai, jb) } else { (b, a, bi, ja) };
                let dr = layout.reduced[row].2;
                match (&mut self.h, pattern) {
                    (Reduced::Dense(m), _) => {
                        let (rr, rc) = (layout.reduced[row].1, layout.reduced[col].1);
                        add_atb(m.as_mut_slice(), n_red, (rr, rc), 1.0, (&rowmajor[tr], dr), (jc, rdim), row == col);
                    }
                    (Reduced::Sparse(blocks), Some(p)) => {
                        let block = if row == col { p.diag_block.get(row) } else { p.index.get(&(row, col)) };
                        if let Some(&i) = block {
                            add_atb(
                                blocks[i].as_mut_slice(),
                                dr,
                                (0, 0),
                                1.0,
                                (&rowmajor[tr], dr),
                                (jc, rdim),
                                row == col,
                            );
                        }
                    }
                    (Reduced::Sparse(_), None) => {}
                }
            }
        }
    }

    /// Adds factor `i`'s part for its eliminated variable `ev` (Jacobian block `je`): to `H_ee`, `g_e`
    /// and the `C` block of each of the factor's reduced variables linked to it.
    fn add_eliminated(&mut self, layout: &Layout, lins: &Lins, i: usize, (ev, je): (usize, &[f64]), r: &[f64]) {
        let rdim = r.len();
        let de = layout.eliminated[ev].1;
        let (ho, go) = layout.elim_off[ev];
        atb_add(&mut self.hee[ho..ho + de * de], je, je, rdim, de, de);
        atb_add(&mut self.ge[go..go + de], je, r, rdim, de, 1);
        let kl = layout.key_link_start[i];
        for (t, &l) in layout.key_link[kl..layout.key_link_start[i + 1]].iter().enumerate() {
            if l == usize::MAX {
                continue;
            }
            let (ja, _) = lins.jacobian(i, t);
            let dr = layout.reduced[layout.link_var[l]].2;
            atb_add(&mut self.c[layout.link_off[l]..layout.link_off[l + 1]], je, ja, rdim, de, dr);
        }
    }
}

/// Largest dense reduced system whose Schur complement is accumulated in [`BlockLower`] (its lower block
/// triangle, about `n²/2` values, is a second copy; above this size the O(n³) factorisation dominates
/// the solve and the copy would only cost memory).
const BLOCKED_SCHUR_MAX: usize = 4000;

/// The lower block triangle of the dense reduced matrix with every block contiguous (column-major), so
/// that the Schur updates of one eliminated variable touch a few contiguous runs of memory instead of
/// columns a whole matrix apart. Each entry receives the same operations in the same order as in the
/// dense matrix, so the result is bit-identical.
struct BlockLower {
    /// Start of block `(a, b)`, `a ≥ b`, at `a (a + 1) / 2 + b`.
    off: Vec<usize>,
    data: Vec<f64>,
}

impl BlockLower {
    fn new(m: &DMatrix<f64>, layout: &Layout) -> Self {
        let n = layout.reduced.len();
        let mut off = Vec::with_capacity(n * (n + 1) / 2);
        let mut data = Vec::new();
        for a in 0..n {
            let (_, ra, da) = layout.reduced[a];
            for b in 0..=a {
                let (_, rb, db) = layout.reduced[b];
                off.push(data.len());
                for j in 0..db {
                    data.extend_from_slice(&m.as_slice()[(rb + j) * m.nrows() + ra..][..da]);
                }
            }
        }
        Self { off, data }
    }

    fn block_mut(&mut self, a: usize, b: usize) -> &mut [f64] {
        let i = a * (a + 1) / 2 + b;
        let end = self.off.get(i + 1).copied().unwrap_or(self.data.len());
        &mut self.data[self.off[i]..end]
    }

    fn write_back(&self, m: &mut DMatrix<f64>, layout: &Layout) {
        let nr = m.nrows();
        let mut blocks = self.off.iter();
        for a in 0..layout.reduced.len() {
            let (_, ra, da) = layout.reduced[a];
            for b in 0..=a {
                let (_, rb, db) = layout.reduced[b];
                let Some(&o) = blocks.next() else { return };
                for j in 0..db {
                    let start = (rb + j) * nr + ra;
                    m.as_mut_slice()[start..start + da].copy_from_slice(&self.data[o + j * da..o + (j + 1) * da]);
                }
            }
        }
    }
}

/// Solve the damped system for the full step (reduced then eliminated variables), or `None` when a
/// factorisation fails.
fn damped_step(
    layout: &Layout,
    ne: &Normal,
    damp: impl Fn(f64) -> f64,
    pattern: Option<&Pattern>,
) -> Option<(DVector<f64>, Vec<DVector<f64>>)> {
    let n_red: usize = layout.reduced.iter().map(|r| r.2).sum();
    let rhs = ne.g.clone();
    let (dense, vals) = damped_reduced(n_red, ne, &damp, pattern)?;
    // Schur complement of the eliminated variables (dense path: into contiguous blocks when small).
    let blocked = match &dense {
        Some(m) if !layout.eliminated.is_empty() && n_red <= BLOCKED_SCHUR_MAX => Some(BlockLower::new(m, layout)),
        _ => None,
    };
    let mut schur = Schur { n_red, rhs, dense, blocked, vals, pattern };
    let hinvs = schur.eliminate(layout, ne, &damp)?;
    let dred = schur.solve()?;
    if !dred.iter().all(|v| v.is_finite()) {
        return None;
    }
    let delim = back_substitute(layout, ne, &hinvs, &dred);
    Some((dred, delim))
}

/// The damped reduced system of [`damped_step`] while the eliminated variables are taken out of it:
/// its right-hand side and its matrix (dense, possibly with a blocked copy, or sparse CSC values).
struct Schur<'p> {
    n_red: usize,
    rhs: DVector<f64>,
    dense: Option<DMatrix<f64>>,
    blocked: Option<BlockLower>,
    vals: Vec<f64>,
    pattern: Option<&'p Pattern>,
}

impl Schur<'_> {
    /// Takes every eliminated variable out of the system by the Schur complement, returning their
    /// damped `H_ee⁻¹` (`None` when one is not positive definite or a block is missing).
    fn eliminate(&mut self, layout: &Layout, ne: &Normal, damp: &impl Fn(f64) -> f64) -> Option<Vec<HInv>> {
        let mut hinvs = Vec::with_capacity(layout.eliminated.len());
        let mut vt: Vec<Vec<f64>> = Vec::new();
        let mut prod = DMatrix::zeros(0, 0);
        let mut pair = 0; // running index of the link pairs ([`Pattern::schur_blocks`])
        for (ev, &(_, de)) in layout.eliminated.iter().enumerate() {
            let (ho, go) = layout.elim_off[ev];
            let (hee, ge) = (&ne.hee[ho..ho + de * de], &ne.ge[go..go + de]);
            // this variable's links: (reduced var, C block)
            let links = (layout.link_start[ev]..layout.link_start[ev + 1])
                .map(|l| (layout.link_var[l], &ne.c[layout.link_off[l]..layout.link_off[l + 1]]));
            let hinv = damped_inverse(hee, de, damp)?;
            let hg: Vec<f64> = hinv.mul_vec(ge);
            let n_links = layout.link_start[ev + 1] - layout.link_start[ev];
            while vt.len() < n_links {
                vt.push(Vec::new());
            }
            for (ai, (a, ca)) in links.clone().enumerate() {
                let (_, ra, da) = layout.reduced[a];
                hinv.mul_mat_rowmajor(ca, da, &mut vt[ai]);
                // rhs_a −= C_aᵀ H⁻¹ g_e
                for (i, col) in ca.chunks_exact(de).enumerate().take(da) {
                    let dot: f64 = col.iter().zip(&hg).map(|(x, y)| x * y).sum();
                    self.rhs[ra + i] -= dot;
                }
            }
            for (ai, (a, _)) in links.clone().enumerate() {
                for (b, cb) in links.clone().take(ai + 1) {
                    pair += 1;
                    self.subtract_pair(layout, (a, &vt[ai]), (b, cb), de, pair, &mut prod)?;
                }
            }
            hinvs.push(hinv);
        }
        if let (Some(m), Some(bl)) = (self.dense.as_mut(), self.blocked.as_ref()) {
            bl.write_back(m, layout);
        }
        Some(hinvs)
    }

    /// `S_ab −= C_aᵀ H⁻¹ C_b = V_aᵀ C_b` for the link pair numbered `pair` (from 1) of an eliminated
    /// variable of dimension `de`, into whichever form the matrix has (`prod` is scratch for the sparse
    /// path; `None` when the pattern lacks the pair).
    fn subtract_pair(
        &mut self,
        layout: &Layout,
        (a, va): (usize, &[f64]),
        (b, cb): (usize, &[f64]),
        de: usize,
        pair: usize,
        prod: &mut DMatrix<f64>,
    ) -> Option<()> {
        let (_, ra, da) = layout.reduced[a];
        let (_, rb, db) = layout.reduced[b];
        if let Some(bl) = self.blocked.as_mut() {
            add_atb(bl.block_mut(a, b), da, (0, 0), -1.0, (va, da), (cb, de), a == b);
        } else if let Some(m) = self.dense.as_mut() {
            add_atb(m.as_mut_slice(), self.n_red, (ra, rb), -1.0, (va, da), (cb, de), a == b);
        } else if let Some(pat) = self.pattern {
            let i = *pat.schur_blocks.get(pair - 1)?;
            if prod.shape() != (da, db) {
                *prod = DMatrix::zeros(da, db);
            }
            prod.fill(0.0);
            add_atb(prod.as_mut_slice(), da, (0, 0), 1.0, (va, da), (cb, de), a == b);
            for (x, &q) in prod.iter().zip(&pat.positions[i]) {
                if q != usize::MAX {
                    self.vals[q] -= x;
                }
            }
        }
        Some(())
    }

    /// The reduced step from the Schur complement: dense or sparse Cholesky (`None` when it fails).
    fn solve(self) -> Option<DVector<f64>> {
        Some(if self.n_red == 0 {
            DVector::zeros(0)
        } else if let Some(m) = self.dense {
            dense_solve(&m, &self.rhs)?
        } else {
            let pat = self.pattern?;
            sparse_solve(pat, &self.vals, &self.rhs)?
        })
    }
}

/// The damped reduced matrix of [`damped_step`]: dense, or the CSC values following the sparse
/// pattern (`None` for a sparse system without one).
fn damped_reduced(
    n_red: usize,
    ne: &Normal,
    damp: &impl Fn(f64) -> f64,
    pattern: Option<&Pattern>,
) -> Option<(Option<DMatrix<f64>>, Vec<f64>)> {
    let mut dense = None;
    let mut vals = Vec::new();
    match (&ne.h, pattern) {
        (Reduced::Dense(m), _) => {
            let mut m = m.clone();
            for i in 0..n_red {
                let v = m[(i, i)];
                m[(i, i)] += damp(v);
            }
            dense = Some(m);
        }
        (Reduced::Sparse(blocks), Some(pat)) => {
            vals = vec![0.0; pat.symbolic.row_idx().len()];
            for (blk, pos) in blocks.iter().zip(&pat.positions) {
                for (v, &q) in blk.iter().zip(pos) {
                    if q != usize::MAX {
                        vals[q] += v;
                    }
                }
            }
            for &q in &pat.diag {
                let v = vals[q];
                vals[q] += damp(v);
            }
        }
        (Reduced::Sparse(_), None) => return None,
    }
    Some((dense, vals))
}

/// `H_ee⁻¹` of one eliminated variable with its diagonal damped, fixed-size for points (`None` when
/// the damped block is not positive definite).
fn damped_inverse(hee: &[f64], de: usize, damp: &impl Fn(f64) -> f64) -> Option<HInv> {
    Some(if de == 3 {
        let mut h = nalgebra::Matrix3::from_column_slice(hee);
        for i in 0..3 {
            let x = h[(i, i)];
            h[(i, i)] += damp(x);
        }
        HInv::Three(h.cholesky()?.inverse())
    } else {
        let mut h = DMatrix::from_column_slice(de, de, hee);
        for i in 0..de {
            let x = h[(i, i)];
            h[(i, i)] += damp(x);
        }
        HInv::Dyn(h.cholesky()?.inverse())
    })
}

/// The eliminated variables' steps from the reduced one: `δ_e = −H_ee⁻¹ (g_e + Σ C δ_r)`.
fn back_substitute(layout: &Layout, ne: &Normal, hinvs: &[HInv], dred: &DVector<f64>) -> Vec<DVector<f64>> {
    let mut delim = Vec::with_capacity(layout.eliminated.len());
    for ((ev, &(_, de)), hinv) in layout.eliminated.iter().enumerate().zip(hinvs) {
        let go = layout.elim_off[ev].1;
        let mut t = DVector::from_column_slice(&ne.ge[go..go + de]);
        for l in layout.link_start[ev]..layout.link_start[ev + 1] {
            let (_, off, d) = layout.reduced[layout.link_var[l]];
            t.gemv(1.0, &view(&ne.c[layout.link_off[l]..layout.link_off[l + 1]], de), &dred.rows(off, d), 1.0);
        }
        let x = hinv.mul_vec(t.as_slice());
        delim.push(-DVector::from_vec(x));
    }
    delim
}

/// `m[ra.., rb..] += alpha · Aᵀ B` on a column-major buffer with leading dimension `ld`, where `at` holds
/// `A` (r × da) row by row (`at[k·da + i] = A(k, i)`) and `b` holds `B` (r × db) column-major. The
/// inner loop is an axpy over contiguous memory, which the compiler vectorises; this is the hot loop of
/// the normal equations and of the Schur complement.
///
/// With `lower`, the block is a diagonal block of a symmetric matrix of which only the lower triangle
/// is read, and the general-size path updates only the entries on or below its diagonal.
///
/// The common block sizes (9-parameter BAL cameras and 6-dof poses against 2-, 3- and 4-row residuals
/// or 3-dof points) go to a copy with compile-time sizes, whose loops the compiler unrolls and
/// vectorises; it updates the whole block (skipping the upper triangle of a diagonal block costs more
/// in branching than it saves). The arithmetic and its order are the same, so the result is
/// bit-identical.
#[inline]
fn add_atb(
    m: &mut [f64],
    ld: usize,
    (ra, rb): (usize, usize),
    alpha: f64,
    (at, da): (&[f64], usize),
    (b, r): (&[f64], usize),
    lower: bool,
) {
    let db = b.len().checked_div(r).unwrap_or(0);
    macro_rules! fixed {
        ($($da:literal, $r:literal, $db:literal);*) => {
            match (da, r, db) {
                $(($da, $r, $db) => return add_atb_fixed::<$da, $r, $db>(m, ld, (ra, rb), alpha, at, b),)*
                _ => {}
            }
        };
    }
    fixed!(9, 2, 9; 9, 3, 9; 6, 2, 6; 6, 3, 6; 6, 4, 6; 6, 3, 3; 3, 3, 6; 6, 6, 6);
    add_atb_dyn(m, ld, (ra, rb), alpha, (at, da), (b, r), lower);
}

/// [`add_atb`] with compile-time sizes `A` (R × DA), `B` (R × DB).
#[inline(always)]
fn add_atb_fixed<const DA: usize, const R: usize, const DB: usize>(
    m: &mut [f64],
    ld: usize,
    (ra, rb): (usize, usize),
    alpha: f64,
    at: &[f64],
    b: &[f64],
) {
    let (at, b) = (&at[..DA * R], &b[..R * DB]);
    for j in 0..DB {
        let start = (rb + j) * ld + ra;
        let col = &mut m[start..start + DA];
        // the column in registers while the R updates are added (same order, one load and store)
        let mut acc = [0.0; DA];
        acc.copy_from_slice(col);
        for k in 0..R {
            let f = alpha * b[j * R + k];
            let ak = &at[k * DA..(k + 1) * DA];
            for (o, a) in acc.iter_mut().zip(ak) {
                *o += f * a;
            }
        }
        col.copy_from_slice(&acc);
    }
}

/// [`add_atb`] for any sizes.
fn add_atb_dyn(
    m: &mut [f64],
    ld: usize,
    (ra, rb): (usize, usize),
    alpha: f64,
    (at, da): (&[f64], usize),
    (b, r): (&[f64], usize),
    lower: bool,
) {
    for (j, bj) in b.chunks_exact(r.max(1)).enumerate() {
        let i0 = if lower { j.min(da) } else { 0 };
        let start = (rb + j) * ld + ra;
        let col = &mut m[start + i0..start + da];
        for (k, &bkj) in bj.iter().enumerate() {
            let f = alpha * bkj;
            let ak = &at[k * da + i0..(k + 1) * da];
            for (o, a) in col.iter_mut().zip(ak) {
                *o += f * a;
            }
        }
    }
}

/// Row-major copy of a column-major matrix into `out`.
#[inline]
fn transpose_into(a: &[f64], r: usize, out: &mut Vec<f64>) {
    let c = a.len().checked_div(r).unwrap_or(0);
    out.clear();
    out.resize(r * c, 0.0);
    for (i, col) in a.chunks_exact(r.max(1)).enumerate() {
        for (k, v) in col.iter().enumerate() {
            out[k * c + i] = *v;
        }
    }
}

/// `½‖r‖² − ½‖r + Jδ‖²` summed over factors (the decrease the linear model predicts).
fn model_decrease(graph: &Graph, layout: &Layout, lins: &Lins, dred: &DVector<f64>, delim: &[DVector<f64>]) -> f64 {
    let mut total = 0.0;
    let mut jd = DVector::zeros(0);
    for (i, e) in graph.entries().iter().enumerate() {
        let r = nalgebra::DVectorView::from_slice(lins.residual(i), lins.r_off[i + 1] - lins.r_off[i]);
        if jd.len() != r.len() {
            jd = DVector::zeros(r.len());
        } else {
            jd.fill(0.0);
        }
        for (t, k) in e.factor.keys().iter().enumerate() {
            let (js, rows) = lins.jacobian(i, t);
            match layout.slots.get(k.0).copied().flatten() {
                Some(Slot::Reduced { var }) => {
                    let (_, off, d) = layout.reduced[var];
                    jd.gemv(1.0, &view(js, rows), &dred.rows(off, d), 1.0);
                }
                Some(Slot::Eliminated { var }) => jd.gemv(1.0, &view(js, rows), &delim[var], 1.0),
                None => {}
            }
        }
        total -= r.dot(&jd) + 0.5 * jd.norm_squared();
    }
    total
}

/// Solve `S δ = −rhs` for a dense symmetric `S` (lower triangle read) with faer's blocked Cholesky.
fn dense_solve(m: &DMatrix<f64>, rhs: &DVector<f64>) -> Option<DVector<f64>> {
    use faer::linalg::solvers::Solve;
    let n = rhs.len();
    let fm = faer::MatRef::from_column_major_slice(m.as_slice(), n, n);
    let llt = fm.llt(faer::Side::Lower).ok()?;
    let mut b = faer::Mat::<f64>::from_fn(n, 1, |i, _| -rhs[i]);
    llt.solve_in_place(b.as_mut());
    Some(DVector::from_fn(n, |i, _| b[(i, 0)]))
}

/// Solve the reduced system `S δ = −rhs` with faer's sparse Cholesky (lower triangle in `vals`,
/// following the pattern), reusing the symbolic factorisation.
fn sparse_solve(pat: &Pattern, vals: &[f64], rhs: &DVector<f64>) -> Option<DVector<f64>> {
    use faer::{
        dyn_stack::{MemBuffer, MemStack},
        sparse::SparseColMatRef,
        Conj, Par, Side,
    };
    let n = rhs.len();
    let mat = SparseColMatRef::new(pat.symbolic.as_ref(), vals);
    let mut l_values = vec![0.0f64; pat.llt.len_val()];
    let req = pat
        .llt
        .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())
        .or(pat.llt.solve_in_place_scratch::<f64>(1, Par::Seq));
    let mut buf = MemBuffer::try_new(req).ok()?;
    let stack = MemStack::new(&mut buf);
    let llt = pat
        .llt
        .factorize_numeric_llt(&mut l_values, mat, Side::Lower, Default::default(), Par::Seq, stack, Default::default())
        .ok()?;
    let mut b = faer::Mat::<f64>::from_fn(n, 1, |i, _| -rhs[i]);
    llt.solve_in_place_with_conj(Conj::No, b.as_mut(), Par::Seq, MemStack::new(&mut buf));
    Some(DVector::from_fn(n, |i, _| b[(i, 0)]))
}

/// Where every trust-region backend starts: the linear system of `graph` at `values`, its first
/// linearisation, and a [`crate::Summary`] holding the initial cost. `Ok(Err(summary))` is a finished
/// solve (nothing is free to move); a factor that cannot be evaluated, or a non-finite cost, is an error.
#[allow(clippy::type_complexity)]
pub fn start(
    graph: &Graph,
    values: &Values,
    options: &crate::Options,
    started: std::time::Instant,
) -> Result<Result<(LinearSystem, Linearization, crate::Summary), crate::Summary>, OptimError> {
    let sys = LinearSystem::new(graph, values, options.dense_limit)?;
    let lin =
        sys.linearize(graph, values).map_err(|(factor, source)| OptimError::InitialEvaluation { factor, source })?;
    if !lin.cost.is_finite() {
        return Err(OptimError::NonFiniteCost);
    }
    let mut summary = crate::Summary {
        initial_cost: lin.cost,
        final_cost: lin.cost,
        iterations: 0,
        accepted: 0,
        termination: crate::Termination::MaxIterations,
        elapsed: std::time::Duration::ZERO,
        reduced_dim: sys.reduced_dim(),
        sparse: sys.is_sparse(),
    };
    if !sys.has_free_variables() {
        summary.termination = crate::Termination::NoFreeVariables;
        summary.elapsed = started.elapsed();
        return Ok(Err(summary));
    }
    Ok(Ok((sys, lin, summary)))
}

/// Where a trust-region solve stands between iterations: its problem and linear system, the
/// linearisation and cost at the current values, the report so far, and the observer told of each
/// iteration.
pub struct Progress<'p, 'o> {
    /// The linear system of the problem.
    pub sys: LinearSystem,
    /// The problem.
    pub graph: &'p Graph,
    /// The common settings.
    pub options: &'p crate::Options,
    /// The linearisation at the current values.
    pub lin: Linearization,
    /// The cost of the current values.
    pub cost: f64,
    /// The report so far.
    pub summary: crate::Summary,
    /// Told of every iteration.
    pub observer: Option<&'o mut dyn crate::Observer>,
}

/// A trial point: the values after a step, their cost, the decrease from the current cost and its ratio
/// to the decrease the linear model predicted (the gain ratio).
pub struct Trial {
    /// The values after the step.
    pub values: Values,
    /// Their cost.
    pub cost: f64,
    /// The current cost minus the trial cost.
    pub change: f64,
    /// `change` over the model's decrease (minus infinity when the model predicts none).
    pub rho: f64,
}

impl Trial {
    /// Whether the trial cost is finite and the gain ratio above `min_relative_decrease`.
    pub fn acceptable(&self, min_relative_decrease: f64) -> bool {
        self.cost.is_finite() && self.rho > min_relative_decrease
    }
}

impl Progress<'_, '_> {
    /// Runs `iteration` (after counting it) until it ends the solve or the checks before each iteration
    /// do (the iteration cap, then the gradient tolerance), and records why the solve ended.
    pub fn iterate(&mut self, mut iteration: impl FnMut(&mut Self) -> Result<(), crate::Termination>) {
        use crate::Termination;
        self.summary.termination = loop {
            if self.summary.iterations >= self.options.max_iterations {
                break Termination::MaxIterations;
            }
            if self.sys.gradient_max(&self.lin) <= self.options.gradient_tolerance {
                break Termination::GradientTolerance;
            }
            self.summary.iterations += 1;
            if let Err(termination) = iteration(self) {
                break termination;
            }
        };
    }

    /// The report of the current iteration before its step is tried: cost unchanged, not accepted.
    pub fn info(&self, radius: f64, step_norm: f64) -> crate::IterationInfo {
        crate::IterationInfo {
            iteration: self.summary.iterations,
            cost: self.cost,
            cost_change: f64::NAN,
            radius,
            step_norm,
            accepted: false,
        }
    }

    /// Tells the observer, if any, of an iteration.
    pub fn notify(&mut self, info: &crate::IterationInfo) {
        if let Some(obs) = self.observer.as_deref_mut() {
            obs.on_iteration(info);
        }
    }

    /// Ends the solve (after telling the observer of the iteration) when the step of `info` is within the
    /// parameter tolerance of the size of `values`.
    pub fn check_step(&mut self, values: &Values, info: &crate::IterationInfo) -> Result<(), crate::Termination> {
        let options = self.options;
        let x_norm = values.iter().map(|(_, v)| v.norm_squared()).sum::<f64>().sqrt();
        if info.step_norm <= options.parameter_tolerance * (x_norm + options.parameter_tolerance) {
            self.notify(info);
            return Err(crate::Termination::ParameterTolerance);
        }
        Ok(())
    }

    /// The trial point of `step` from `values`, or `None` when a factor cannot be evaluated there.
    pub fn trial(&self, values: &Values, step: &Step) -> Option<Trial> {
        let (sys, graph) = (&self.sys, self.graph);
        let model = sys.model_decrease(graph, &self.lin, step);
        let trial = sys.retract(values, step);
        let new_cost = sys.cost(graph, &trial).ok()?;
        let change = self.cost - new_cost;
        let rho = if model > 0.0 { change / model } else { f64::NEG_INFINITY };
        Some(Trial { values: trial, cost: new_cost, change, rho })
    }

    /// Moves `values` to an accepted trial point, counts the step in the report and in `info`, and
    /// linearises there. Ends the solve when the relative cost decrease is within the function
    /// tolerance (telling the observer of the iteration; no new linearisation) or when the new point
    /// cannot be linearised.
    pub fn accept(
        &mut self,
        values: &mut Values,
        trial: Trial,
        info: &mut crate::IterationInfo,
    ) -> Result<(), crate::Termination> {
        *values = trial.values;
        let rel = trial.change.abs() / self.cost.max(f64::MIN_POSITIVE);
        self.cost = trial.cost;
        self.summary.accepted += 1;
        info.cost = self.cost;
        if rel < self.options.function_tolerance {
            self.notify(&crate::IterationInfo { accepted: true, ..*info });
            return Err(crate::Termination::FunctionTolerance);
        }
        let lin = self.sys.linearize(self.graph, values).map_err(|_| crate::Termination::NoProgress)?;
        self.cost = lin.cost;
        self.lin = lin;
        Ok(())
    }
}
