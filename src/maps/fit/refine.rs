//! Coarse to fine: the maps of a fine texel grid from those of a grid of half its resolution,
//! fitted to the photos at half their resolution (each coarse pixel the mean of a 2 x 2 block,
//! [`ShadingRecords::coarsened`]).
//!
//! The bases are global: their number, their centres, the roughness floor and whether the
//! texels have normals are chosen once, at the coarsest grid (stage 5 of the module table of
//! [`super`]), on a sixteenth of the pixels at a quarter of the resolution. Each finer grid then
//! solves every texel once under the basis of the coarse texel it lies in (stage 4's texel
//! solve, from that texel's coordinates), and, where the coarse texels around it hold other
//! bases too (a material edge), once under each of those, the labels chosen among them with
//! the same Potts prior as stage 3 ([`label_smoothing`]). This is the coarse-to-fine strategy
//! of the per-pixel SVBRDF optimisers (MaterialGAN, Guo et al. 2020, section 5: 256 to 512 to
//! 1024), with the difference that the coarse grid's job is the choice of the bases and of each
//! texel's basis, and the fine grid's the texels' own values: a fine texel costs one solve of
//! its own pixels in place of the `2 (ALPHA_STARTS + K) + 1` of stages 1 to 4.

use super::*;

/// Stage 2 at a fine grid runs on the texels of every `NOISE_STRIDE`-th row and column (a
/// sixteenth of them): the noise level is one number, and stages 1 and 2 on every texel would
/// cost four solves a texel.
const NOISE_STRIDE: usize = 4;

/// The records and grid a maps fit of `options.grid` is refined from, when the grid has more
/// than `options.coarsest` texels: the grid halved, and the photos halved too
/// ([`ShadingRecords::coarsened`], `Some`), so that a texel sees as many pixels as before
/// (`None` where a photo is too small to halve: the same records).
pub(super) fn coarser(
    records: &ShadingRecords,
    options: &MapsFitOptions,
) -> Option<(Option<ShadingRecords>, TexelGrid)> {
    let grid = options.grid;
    if grid.len() <= options.coarsest? || grid.width < 2 || grid.height < 2 {
        return None;
    }
    let coarse = TexelGrid {
        width: grid.width.div_ceil(2),
        height: grid.height.div_ceil(2),
    };
    Some((records.coarsened(), coarse))
}

/// The maps of `options.grid` refined from `coarse`, fitted on `coarse_grid` (see the module
/// docs).
pub(super) fn refine(
    records: &ShadingRecords,
    options: &MapsFitOptions,
    space: ParamSpace,
    coarse: Level,
    coarse_grid: TexelGrid,
) -> Result<Level> {
    let normals = coarse.normals;
    let model = TexelModel {
        space,
        normals,
        records,
        lobe_directions: None,
    };
    let grid = options.grid;
    let held_out = options.held_out_photo.as_slice();
    let blocks = TexelBlocks::new(records, grid, 1, held_out);
    let noise_sample = TexelBlocks::new(records, grid, NOISE_STRIDE, held_out);
    let sigma2 = independent_texels(&model, &noise_sample).sigma2;
    let refined = |model: &TexelModel, blocks: &TexelBlocks, what: &str| {
        let (mut texels, labels) = refined_texels(
            model,
            blocks,
            &coarse,
            coarse_grid,
            sigma2,
            &options.progress,
            what,
        )?;
        let seen = blocks.seen();
        let mut clusters = Clusters {
            centres: coarse.prior_centres.clone(),
            kinds: coarse.kinds.clone(),
            assignment: labels,
        };
        clusters.drop_empty(&seen);
        clusters.recentre(&texels, &seen, model.specular_dim(), model.roughness_dim());
        settle(model, blocks, &mut texels, &mut clusters, sigma2);
        Ok::<_, Error>((texels, clusters))
    };
    // The roughness floor, chosen anew: a texel of a coarse grid averages its pixels' highlights
    // into a rougher lobe, and the floor chosen there is too rough for the finer grid.
    let roughness_floor = match options.validation_photo {
        Some(photo) if !coarse.basis_trials.is_empty() => {
            let unseen: Vec<usize> = held_out.iter().copied().chain([photo]).collect();
            let sample = TexelBlocks::new(records, grid, 2, &unseen);
            let (texels, _) = refined(&model, &sample, "choosing the roughness floor")?;
            let validation = validation_pixels(records, grid, photo);
            best_floor(&model, &texels, grid, &validation).floor
        }
        _ => None,
    };
    let (texels, clusters) = refined(&model, &blocks, "")?;
    let (bases, prior_centres) = reported_bases(&model, &blocks, &texels, &clusters, sigma2);
    let mut texels = with_roughness_floor(texels, model.roughness_dim(), roughness_floor);
    fill_unseen(&mut texels, &blocks);
    Ok(Level {
        texels,
        bases,
        labels: clusters.assignment,
        prior_centres,
        kinds: clusters.kinds,
        sigma2,
        basis_trials: coarse.basis_trials,
        roughness_floor,
        normals,
        normals_trial: coarse.normals_trial,
        bases_grid: coarse.bases_grid,
    })
}

/// Every texel of `blocks` solved as [`texel_options`] says and labelled as in stage 3
/// ([`label_smoothing`]): the texels and their labels. Texels without pixels keep the
/// coordinates of the coarse texel they lie in.
fn refined_texels(
    model: &TexelModel,
    blocks: &TexelBlocks,
    coarse: &Level,
    coarse_grid: TexelGrid,
    sigma2: f64,
    progress: &Reporting,
    what: &str,
) -> Result<(Vec<TexelFit>, Vec<usize>)> {
    let grid = blocks.grid;
    let mut bar = progress.start_with_rate(
        format!("maps {}x{} {what}", grid.width, grid.height).trim_end(),
        grid.len() as u64,
        "texels",
    );
    let options = |t: usize, only: Option<usize>| {
        texel_options(model, blocks, coarse, coarse_grid, t, sigma2, only)
    };
    // Each texel keeps the costs of all its candidate bases but only the solution under the
    // cheapest: at 1024^2 every candidate's solution is a few hundred megabytes more, and the
    // labels differ from the cheapest basis only along a few edges.
    let mut costs: Vec<Vec<(usize, f64)>> = Vec::with_capacity(grid.len());
    let mut texels: Vec<(usize, TexelFit)> = Vec::with_capacity(grid.len());
    // Bands of rows, so that the bar moves while the texels are solved in parallel.
    let band = grid.width * (grid.height / 32).max(1);
    for first in (0..grid.len()).step_by(band) {
        let last = (first + band).min(grid.len());
        let (band_costs, band_texels): (Vec<_>, Vec<_>) = (first..last)
            .into_par_iter()
            .map(|t| {
                let mut candidates = options(t, None);
                let cheapest = (0..candidates.len())
                    .min_by(|&i, &j| candidates[i].1.total_cmp(&candidates[j].1))
                    .expect("a basis for every texel");
                let costs = candidates.iter().map(|&(b, cost, _)| (b, cost)).collect();
                let (basis, _, fit) = candidates.swap_remove(cheapest);
                (costs, (basis, fit))
            })
            .unzip();
        costs.extend(band_costs);
        texels.extend(band_texels);
        bar.step(last as u64, String::new)?;
    }
    bar.finish();
    let labels = label_smoothing(&costs, blocks);
    drop(costs);
    let texels = texels
        .into_par_iter()
        .zip(&labels)
        .enumerate()
        .map(|(t, ((basis, fit), &label))| {
            if basis == label {
                fit
            } else {
                options(t, Some(label))
                    .pop()
                    .expect("the label is a candidate")
                    .2
            }
        })
        .collect();
    Ok((texels, labels))
}

/// Texel `t` solved under each basis of the 3 x 3 coarse texels around the one it lies in
/// (or only under basis `only`, one of them), from the coordinates of the nearest of them with
/// that basis: `(basis, posterior cost, solution)`, the cost as in stage 3 ([`basis_fits`]).
fn texel_options(
    model: &TexelModel,
    blocks: &TexelBlocks,
    coarse: &Level,
    coarse_grid: TexelGrid,
    t: usize,
    sigma2: f64,
    only: Option<usize>,
) -> Vec<(usize, f64, TexelFit)> {
    let grid = blocks.grid;
    // The texel's centre in coarse texel units.
    let (x, y) = (
        ((t % grid.width) as f64 + 0.5) * coarse_grid.width as f64 / grid.width as f64,
        ((t / grid.width) as f64 + 0.5) * coarse_grid.height as f64 / grid.height as f64,
    );
    let (cx, cy) = (x as usize, y as usize);
    let around: Vec<usize> = (cy.saturating_sub(1)..(cy + 2).min(coarse_grid.height))
        .flat_map(|r| {
            (cx.saturating_sub(1)..(cx + 2).min(coarse_grid.width))
                .map(move |c| r * coarse_grid.width + c)
        })
        .collect();
    let distance = |n: usize| {
        let (c, r) = (
            (n % coarse_grid.width) as f64 + 0.5,
            (n / coarse_grid.width) as f64 + 0.5,
        );
        (c - x).powi(2) + (r - y).powi(2)
    };
    let pixels = blocks.of(t);
    let mut bases: Vec<usize> = if pixels.is_empty() {
        vec![coarse.labels[cy * coarse_grid.width + cx]]
    } else {
        around.iter().map(|&n| coarse.labels[n]).collect()
    };
    bases.sort_unstable();
    bases.dedup();
    bases
        .into_iter()
        .filter(|&b| only.is_none_or(|only| only == b))
        .map(|b| {
            let from = around
                .iter()
                .copied()
                .filter(|&n| coarse.labels[n] == b)
                .min_by(|&m, &n| distance(m).total_cmp(&distance(n)))
                .expect("a coarse texel of the basis");
            let start = &coarse.texels[from];
            let basis = (coarse.kinds[b], coarse.prior_centres[b].as_slice());
            let (posterior, fit) =
                model.solve_under_basis(start, start.kind, basis, pixels, sigma2);
            (b, posterior, fit)
        })
        .collect()
}
