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

/// One factor's weighted, whitened linearisation.
struct Lin {
    r: DVector<f64>,
    /// Per key of the factor: Jacobian block, or `None` when the key is fixed.
    j: Vec<Option<DMatrix<f64>>>,
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
}

struct ElimBlock {
    hee: DMatrix<f64>,
    ge: DVector<f64>,
    /// `(reduced var, J_eᵀ J_r)` blocks, d_e × d_r, sorted by reduced var.
    links: Vec<(usize, DMatrix<f64>)>,
}

/// Block pattern of the reduced system for the sparse path: which `(a, b)` blocks (`a ≥ b`) exist,
/// where their entries sit in the compressed-column lower triangle, and the symbolic factorisation.
struct Pattern {
    index: HashMap<(usize, usize), usize>,
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

impl Pattern {
    fn build(layout: &Layout, graph: &Graph) -> Option<Self> {
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
        let pairs: Vec<(usize, usize)> = pairs.into_iter().collect();
        let n: usize = layout.reduced.iter().map(|r| r.2).sum();
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
        let symbolic = faer::sparse::SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        use faer::sparse::linalg::{
            cholesky::{factorize_symbolic_cholesky, CholeskySymbolicParams, SymmetricOrdering},
            SupernodalThreshold,
        };
        let llt = factorize_symbolic_cholesky(
            symbolic.as_ref(),
            faer::Side::Lower,
            SymmetricOrdering::Amd,
            CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
                ..Default::default()
            },
        )
        .ok()?;
        let index = pairs.iter().enumerate().map(|(i, p)| (*p, i)).collect();
        Some(Self { index, positions, pairs, diag, symbolic, llt })
    }
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

    /// `out` = row-major `H⁻¹ C` (d_e × n).
    fn mul_mat_rowmajor(&self, c: &DMatrix<f64>, out: &mut Vec<f64>) {
        let (de, n) = c.shape();
        out.clear();
        out.resize(de * n, 0.0);
        let cs = c.as_slice();
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
    elim: Vec<ElimBlock>,
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
    lins: Vec<Lin>,
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
        lin.ne.g.amax().max(lin.ne.elim.iter().map(|e| e.ge.amax()).fold(0.0, f64::max))
    }

    /// The gradient `Jᵀr` as a step.
    pub fn gradient(&self, lin: &Linearization) -> Step {
        Step { reduced: lin.ne.g.clone(), eliminated: lin.ne.elim.iter().map(|e| e.ge.clone()).collect() }
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

fn layout(graph: &Graph, values: &Values) -> Result<Layout, OptimError> {
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
    Ok(Layout { slots, reduced, eliminated })
}

fn linearize(graph: &Graph, values: &Values, jac: bool) -> Result<(f64, Vec<Lin>), (usize, FactorError)> {
    let mut cost = 0.0;
    let mut lins = Vec::with_capacity(if jac { graph.entries().len() } else { 0 });
    let mut buf = Vec::new();
    for (i, e) in graph.entries().iter().enumerate() {
        let mut r = e.factor.evaluate(values, if jac { Some(&mut buf) } else { None }).map_err(|err| (i, err))?;
        e.noise.whiten(&mut r);
        let s = r.norm_squared();
        let [rho, d1, _] = e.kernel.evaluate(s);
        if !rho.is_finite() {
            return Err((i, FactorError::Undefined("non-finite residual".into())));
        }
        cost += 0.5 * rho;
        if jac {
            let w = d1.max(0.0).sqrt();
            r *= w;
            let j = e
                .factor
                .keys()
                .iter()
                .zip(buf.drain(..))
                .map(|(k, mut jk)| {
                    if graph.is_fixed(*k) {
                        None
                    } else {
                        e.noise.whiten_jacobian(&mut jk);
                        jk *= w;
                        Some(jk)
                    }
                })
                .collect();
            lins.push(Lin { r, j });
        }
    }
    Ok((cost, lins))
}

fn normal_equations(graph: &Graph, layout: &Layout, lins: &[Lin], pattern: Option<&Pattern>) -> Normal {
    let n_red: usize = layout.reduced.iter().map(|r| r.2).sum();
    let mut h = match pattern {
        None => Reduced::Dense(DMatrix::zeros(n_red, n_red)),
        Some(p) => Reduced::Sparse(
            p.pairs.iter().map(|&(a, b)| DMatrix::zeros(layout.reduced[a].2, layout.reduced[b].2)).collect(),
        ),
    };
    let mut g = DVector::zeros(n_red);
    let mut elim: Vec<ElimBlock> = layout
        .eliminated
        .iter()
        .map(|&(_, d)| ElimBlock { hee: DMatrix::zeros(d, d), ge: DVector::zeros(d), links: Vec::new() })
        .collect();
    let mut red: Vec<(usize, &DMatrix<f64>)> = Vec::new();
    let mut rowmajor: Vec<Vec<f64>> = Vec::new();
    for (e, lin) in graph.entries().iter().zip(lins) {
        red.clear();
        let mut el: Option<(usize, &DMatrix<f64>)> = None;
        for (k, j) in e.factor.keys().iter().zip(&lin.j) {
            let Some(j) = j else { continue };
            match layout.slots.get(k.0).copied().flatten() {
                Some(Slot::Reduced { var }) => red.push((var, j)),
                Some(Slot::Eliminated { var }) => el = Some((var, j)),
                None => {}
            }
        }
        while rowmajor.len() < red.len() {
            rowmajor.push(Vec::new());
        }
        for (ai, &(_, ja)) in red.iter().enumerate() {
            transpose_into(ja, &mut rowmajor[ai]);
        }
        let rdim = lin.r.len();
        for ai in 0..red.len() {
            let (a, ja) = red[ai];
            let (_, ra, da) = layout.reduced[a];
            g.rows_mut(ra, da).gemv_tr(1.0, ja, &lin.r, 1.0);
            for (bi, &(b, jb)) in red[..=ai].iter().enumerate() {
                // H_rc += J_rᵀ J_c with r ≥ c
                let (row, col, tr, jc) = if a >= b { (a, b, ai, jb) } else { (b, a, bi, ja) };
                let dr = layout.reduced[row].2;
                match (&mut h, pattern) {
                    (Reduced::Dense(m), _) => {
                        let (rr, rc) = (layout.reduced[row].1, layout.reduced[col].1);
                        add_atb(m.as_mut_slice(), n_red, (rr, rc), 1.0, (&rowmajor[tr], dr), (jc.as_slice(), rdim));
                    }
                    (Reduced::Sparse(blocks), Some(p)) => {
                        if let Some(&i) = p.index.get(&(row, col)) {
                            add_atb(
                                blocks[i].as_mut_slice(),
                                dr,
                                (0, 0),
                                1.0,
                                (&rowmajor[tr], dr),
                                (jc.as_slice(), rdim),
                            );
                        }
                    }
                    (Reduced::Sparse(_), None) => {}
                }
            }
        }
        if let Some((ev, je)) = el {
            let eb = &mut elim[ev];
            eb.hee.gemm_tr(1.0, je, je, 1.0);
            eb.ge.gemv_tr(1.0, je, &lin.r, 1.0);
            for &(a, ja) in &red {
                match eb.links.iter_mut().find(|(v, _)| *v == a) {
                    Some((_, m)) => m.gemm_tr(1.0, je, ja, 1.0),
                    None => eb.links.push((a, je.tr_mul(ja))),
                }
            }
        }
    }
    for eb in &mut elim {
        eb.links.sort_by_key(|(a, _)| *a);
    }
    Normal { h, g, elim }
}

/// Solve the damped system for the full step (reduced then eliminated variables), or `None` when a

fn damped_step(
    layout: &Layout,
    ne: &Normal,
    damp: impl Fn(f64) -> f64,
    pattern: Option<&Pattern>,
) -> Option<(DVector<f64>, Vec<DVector<f64>>)> {
    let n_red: usize = layout.reduced.iter().map(|r| r.2).sum();
    let mut rhs = ne.g.clone();
    // Assemble the damped reduced matrix: dense, or CSC values following the pattern.
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
    // Schur complement of the eliminated variables.
    let mut hinvs = Vec::with_capacity(ne.elim.len());
    let mut vt: Vec<Vec<f64>> = Vec::new();
    let mut prod = DMatrix::zeros(0, 0);
    for eb in &ne.elim {
        let de = eb.hee.nrows();
        // H_ee⁻¹ (damped), fixed-size for points
        let hinv = if de == 3 {
            let mut h = nalgebra::Matrix3::from_column_slice(eb.hee.as_slice());
            for i in 0..3 {
                let x = h[(i, i)];
                h[(i, i)] += damp(x);
            }
            HInv::Three(h.cholesky()?.inverse())
        } else {
            let mut h = eb.hee.clone();
            for i in 0..de {
                let x = h[(i, i)];
                h[(i, i)] += damp(x);
            }
            HInv::Dyn(h.cholesky()?.inverse())
        };
        let hg: Vec<f64> = hinv.mul_vec(eb.ge.as_slice());
        while vt.len() < eb.links.len() {
            vt.push(Vec::new());
        }
        for (ai, (a, ca)) in eb.links.iter().enumerate() {
            hinv.mul_mat_rowmajor(ca, &mut vt[ai]);
            let (_, ra, da) = layout.reduced[*a];
            // rhs_a −= C_aᵀ H⁻¹ g_e
            for (i, col) in ca.as_slice().chunks_exact(de).enumerate().take(da) {
                let dot: f64 = col.iter().zip(&hg).map(|(x, y)| x * y).sum();
                rhs[ra + i] -= dot;
            }
        }
        for (ai, (a, _)) in eb.links.iter().enumerate() {
            let (_, ra, da) = layout.reduced[*a];
            for (b, cb) in &eb.links[..=ai] {
                let (_, rb, db) = layout.reduced[*b];
                // S_ab −= C_aᵀ H⁻¹ C_b = V_aᵀ C_b
                if let Some(m) = dense.as_mut() {
                    add_atb(m.as_mut_slice(), n_red, (ra, rb), -1.0, (&vt[ai], da), (cb.as_slice(), de));
                } else if let Some(pat) = pattern {
                    let i = *pat.index.get(&(*a, *b))?;
                    if prod.shape() != (da, db) {
                        prod = DMatrix::zeros(da, db);
                    }
                    prod.fill(0.0);
                    add_atb(prod.as_mut_slice(), da, (0, 0), 1.0, (&vt[ai], da), (cb.as_slice(), de));
                    for (x, &q) in prod.iter().zip(&pat.positions[i]) {
                        if q != usize::MAX {
                            vals[q] -= x;
                        }
                    }
                }
            }
        }
        hinvs.push(hinv);
    }
    let dred = if n_red == 0 {
        DVector::zeros(0)
    } else if let Some(m) = dense {
        dense_solve(&m, &rhs)?
    } else {
        let pat = pattern?;
        sparse_solve(pat, &vals, &rhs)?
    };
    if !dred.iter().all(|v| v.is_finite()) {
        return None;
    }
    // Back-substitution.
    let mut delim = Vec::with_capacity(ne.elim.len());
    for (eb, hinv) in ne.elim.iter().zip(&hinvs) {
        let mut t = eb.ge.clone();
        for (a, c) in &eb.links {
            let (_, off, d) = layout.reduced[*a];
            t.gemv(1.0, c, &dred.rows(off, d), 1.0);
        }
        let x = hinv.mul_vec(t.as_slice());
        delim.push(-DVector::from_vec(x));
    }
    Some((dred, delim))
}

/// `m[ra.., rb..] += alpha · Aᵀ B` on a column-major buffer with leading dimension `ld`, where `at` holds
/// `A` (r × da) row by row (`at[k·da + i] = A(k, i)`) and `b` holds `B` (r × db) column-major. The
/// inner loop is an axpy over contiguous memory, which the compiler vectorises; this is the hot loop of
/// the normal equations and of the Schur complement.
#[inline]
fn add_atb(
    m: &mut [f64],
    ld: usize,
    (ra, rb): (usize, usize),
    alpha: f64,
    (at, da): (&[f64], usize),
    (b, r): (&[f64], usize),
) {
    for (j, bj) in b.chunks_exact(r).enumerate() {
        let start = (rb + j) * ld + ra;
        let col = &mut m[start..start + da];
        for (k, &bkj) in bj.iter().enumerate() {
            let f = alpha * bkj;
            let ak = &at[k * da..(k + 1) * da];
            for (o, a) in col.iter_mut().zip(ak) {
                *o += f * a;
            }
        }
    }
}

/// Row-major copy of a column-major matrix into `out`.
#[inline]
fn transpose_into(a: &DMatrix<f64>, out: &mut Vec<f64>) {
    let (r, c) = a.shape();
    out.clear();
    out.resize(r * c, 0.0);
    for (i, col) in a.as_slice().chunks_exact(r).enumerate() {
        for (k, v) in col.iter().enumerate() {
            out[k * c + i] = *v;
        }
    }
}

/// `½‖r‖² − ½‖r + Jδ‖²` summed over factors (the decrease the linear model predicts).
fn model_decrease(graph: &Graph, layout: &Layout, lins: &[Lin], dred: &DVector<f64>, delim: &[DVector<f64>]) -> f64 {
    let mut total = 0.0;
    let mut jd = DVector::zeros(0);
    for (e, lin) in graph.entries().iter().zip(lins) {
        if jd.len() != lin.r.len() {
            jd = DVector::zeros(lin.r.len());
        } else {
            jd.fill(0.0);
        }
        for (k, j) in e.factor.keys().iter().zip(&lin.j) {
            let Some(j) = j else { continue };
            match layout.slots.get(k.0).copied().flatten() {
                Some(Slot::Reduced { var }) => {
                    let (_, off, d) = layout.reduced[var];
                    jd.gemv(1.0, j, &dred.rows(off, d), 1.0);
                }
                Some(Slot::Eliminated { var }) => jd.gemv(1.0, j, &delim[var], 1.0),
                None => {}
            }
        }
        total -= lin.r.dot(&jd) + 0.5 * jd.norm_squared();
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
