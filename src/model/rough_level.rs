//! The rough boundary's loss of level, as the photon tally measures it (docs/medium.md, "The
//! rough boundary in the model").
//!
//! GGX microfacets with Smith masking (the renderers' rough dielectric) do not conserve energy,
//! and light that meets the wall many times inside (high albedo) loses more. The loss is not a
//! simple function of the roughness: at albedo 0.99–0.995 the tally over the model is lower at
//! α 0.15 than a power of α through the other nodes allows. Least squares in α^{3/2} (five
//! terms, used until 2026-12-08) missed the tally by up to 1.67% (rms 0.53%) on 40 media off
//! its nodes, fourteen terms in α and α² by 1.22% (rms 0.52%); the tally's own table,
//! interpolated, by 0.79% (rms 0.41%). `medium::rough_level_and_exit_tilt_against_the_photon_tally`
//! prints the table; `medium::rough_level_on_unseen_media` and
//! `medium::the_rough_level_holds_on_unseen_media` check it off the nodes.

/// σt′R of the table's nodes (a 15 mm sphere at σt 0.5, 25 mm at 1, 35 mm at 3 /mm).
pub const SIGMA_T_RADII: [f64; 3] = [7.5, 25.0, 105.0];
/// η of the table's nodes.
pub const ETAS: [f64; 3] = [1.3, 1.45, 1.6];
/// GGX α of the table's nodes.
pub const ALPHAS: [f64; 4] = [0.05, 0.1, 0.15, 0.25];
/// Reduced albedo α′ of the table's nodes.
pub const ALBEDOS: [f64; 9] = [0.6, 0.7, 0.8, 0.85, 0.9, 0.95, 0.97, 0.99, 0.995];

/// The photon tally over the beam model (its level corrected,
/// [`crate::model::sphere_diffusion::level_correction`]) entering through T_α without this
/// loss, M over θ 0–60°, a million photons a node (standard error 0.06–0.2%), indexed
/// [σt′R][η][α][α′] as the node arrays above.
#[rustfmt::skip]
pub const TABLE: [[[[f64; 9]; 4]; 3]; 3] = [
    [
        [
            [1.0040, 0.9942, 0.9925, 0.9926, 0.9951, 0.9890, 0.9876, 0.9827, 0.9820],
            [1.0029, 0.9883, 0.9842, 0.9804, 0.9776, 0.9654, 0.9623, 0.9529, 0.9481],
            [0.9991, 0.9832, 0.9719, 0.9631, 0.9566, 0.9390, 0.9315, 0.9170, 0.9111],
            [0.9840, 0.9635, 0.9375, 0.9233, 0.9050, 0.8795, 0.8645, 0.8425, 0.8339],
        ],
        [
            [1.0042, 0.9952, 0.9897, 0.9913, 0.9924, 0.9895, 0.9906, 0.9816, 0.9781],
            [1.0019, 0.9948, 0.9834, 0.9810, 0.9765, 0.9676, 0.9612, 0.9477, 0.9413],
            [1.0025, 0.9877, 0.9732, 0.9658, 0.9574, 0.9385, 0.9249, 0.9053, 0.8970],
            [0.9885, 0.9677, 0.9410, 0.9266, 0.9054, 0.8715, 0.8529, 0.8205, 0.8078],
        ],
        [
            [1.0054, 0.9986, 0.9941, 0.9943, 0.9918, 0.9917, 0.9888, 0.9820, 0.9769],
            [1.0077, 0.9948, 0.9841, 0.9809, 0.9791, 0.9667, 0.9585, 0.9422, 0.9338],
            [1.0096, 0.9913, 0.9723, 0.9650, 0.9552, 0.9360, 0.9213, 0.8949, 0.8818],
            [0.9996, 0.9772, 0.9464, 0.9253, 0.9046, 0.8646, 0.8409, 0.7961, 0.7802],
        ],
    ],
    [
        [
            [1.0069, 0.9940, 0.9879, 0.9921, 0.9938, 0.9919, 0.9918, 0.9865, 0.9791],
            [1.0045, 0.9905, 0.9819, 0.9811, 0.9788, 0.9713, 0.9660, 0.9539, 0.9461],
            [0.9991, 0.9838, 0.9687, 0.9636, 0.9581, 0.9453, 0.9376, 0.9177, 0.9067],
            [0.9890, 0.9658, 0.9402, 0.9281, 0.9130, 0.8888, 0.8733, 0.8427, 0.8294],
        ],
        [
            [1.0071, 0.9962, 0.9859, 0.9925, 0.9928, 0.9972, 0.9934, 0.9863, 0.9806],
            [1.0060, 0.9970, 0.9826, 0.9811, 0.9781, 0.9726, 0.9663, 0.9501, 0.9417],
            [1.0067, 0.9903, 0.9736, 0.9674, 0.9576, 0.9421, 0.9324, 0.9079, 0.8944],
            [0.9968, 0.9745, 0.9455, 0.9315, 0.9127, 0.8817, 0.8618, 0.8213, 0.8006],
        ],
        [
            [1.0098, 0.9981, 0.9908, 0.9930, 0.9948, 0.9952, 0.9932, 0.9853, 0.9790],
            [1.0054, 0.9995, 0.9826, 0.9818, 0.9793, 0.9728, 0.9661, 0.9467, 0.9354],
            [1.0094, 0.9952, 0.9751, 0.9685, 0.9609, 0.9437, 0.9274, 0.8986, 0.8817],
            [1.0058, 0.9844, 0.9516, 0.9302, 0.9134, 0.8753, 0.8533, 0.8032, 0.7772],
        ],
    ],
    [
        [
            [1.0099, 0.9947, 0.9895, 0.9923, 0.9943, 0.9912, 0.9922, 0.9865, 0.9802],
            [1.0070, 0.9924, 0.9824, 0.9815, 0.9801, 0.9715, 0.9688, 0.9554, 0.9487],
            [1.0026, 0.9859, 0.9685, 0.9657, 0.9605, 0.9478, 0.9392, 0.9199, 0.9094],
            [0.9916, 0.9699, 0.9415, 0.9317, 0.9164, 0.8929, 0.8754, 0.8470, 0.8317],
        ],
        [
            [1.0076, 1.0025, 0.9878, 0.9931, 0.9915, 0.9955, 0.9923, 0.9868, 0.9815],
            [1.0108, 1.0037, 0.9804, 0.9820, 0.9789, 0.9742, 0.9671, 0.9530, 0.9447],
            [1.0101, 0.9955, 0.9744, 0.9681, 0.9608, 0.9462, 0.9359, 0.9119, 0.8993],
            [1.0003, 0.9786, 0.9473, 0.9345, 0.9165, 0.8855, 0.8674, 0.8279, 0.8049],
        ],
        [
            [1.0109, 1.0004, 0.9890, 0.9919, 0.9936, 0.9927, 0.9924, 0.9875, 0.9804],
            [1.0111, 1.0014, 0.9830, 0.9828, 0.9790, 0.9713, 0.9665, 0.9497, 0.9385],
            [1.0127, 0.9993, 0.9770, 0.9693, 0.9600, 0.9450, 0.9336, 0.9030, 0.8879],
            [1.0101, 0.9911, 0.9551, 0.9359, 0.9196, 0.8821, 0.8588, 0.8089, 0.7857],
        ],
    ],
];

/// The factor the rough boundary's losses put on the exitance: [`TABLE`] interpolated linearly
/// in ln σt′R, η, ln α and s = √(1 − α′), held at the table's
/// edges outside it. Below α 0.05 the departure from 1 shrinks as (α/0.05)^{3/2}, to the smooth
/// boundary's 1.
pub fn factor(reduced_albedo: f64, eta: f64, alpha: f64, sigma_t_radius: f64) -> f64 {
    let (k, tk) = bracket(&SIGMA_T_RADII.map(f64::ln), sigma_t_radius.max(1e-9).ln());
    let (e, te) = bracket(&ETAS, eta);
    let (a, ta) = bracket(&ALPHAS.map(f64::ln), alpha.max(1e-9).ln());
    // The albedo's nodes in s, which falls as α′ rises: node i of the reversed array is
    // ALBEDOS[8 − i].
    let s_nodes = std::array::from_fn::<f64, 9, _>(|i| (1.0 - ALBEDOS[8 - i]).sqrt());
    let (b, tb) = bracket(&s_nodes, (1.0 - reduced_albedo).max(0.0).sqrt());
    let mut sum = 0.0;
    for (dk, wk) in [(0, 1.0 - tk), (1, tk)] {
        for (de, we) in [(0, 1.0 - te), (1, te)] {
            for (da, wa) in [(0, 1.0 - ta), (1, ta)] {
                for (db, wb) in [(0, 1.0 - tb), (1, tb)] {
                    sum += wk * we * wa * wb * TABLE[k + dk][e + de][a + da][8 - (b + db)];
                }
            }
        }
    }
    let below = (alpha / ALPHAS[0]).clamp(0.0, 1.0).powf(1.5);
    1.0 + (sum - 1.0) * below
}

/// The cell of ascending `nodes` that holds `v` (held at the ends) and `v`'s place in it, 0–1.
fn bracket(nodes: &[f64], v: f64) -> (usize, f64) {
    let last = nodes.len() - 1;
    let v = v.clamp(nodes[0], nodes[last]);
    let i = (0..last).find(|&i| v <= nodes[i + 1]).unwrap_or(last - 1);
    (i, (v - nodes[i]) / (nodes[i + 1] - nodes[i]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_factor_is_the_table_at_its_nodes_and_between_them_in_between() {
        for (k, &x) in SIGMA_T_RADII.iter().enumerate() {
            for (e, &eta) in ETAS.iter().enumerate() {
                for (a, &alpha) in ALPHAS.iter().enumerate() {
                    for (b, &albedo) in ALBEDOS.iter().enumerate() {
                        let f = factor(albedo, eta, alpha, x);
                        assert!(
                            (f - TABLE[k][e][a][b]).abs() < 1e-12,
                            "{f} at {k} {e} {a} {b}"
                        );
                    }
                }
            }
        }
        // Halfway in s between two albedo nodes, the mean of the two.
        let s = 0.5 * ((1.0f64 - 0.97).sqrt() + (1.0f64 - 0.99).sqrt());
        let mid = factor(1.0 - s * s, 1.45, 0.1, 25.0);
        let want = 0.5 * (TABLE[1][1][1][6] + TABLE[1][1][1][7]);
        assert!((mid - want).abs() < 1e-12, "{mid} against {want}");
        // Held at the edges; 1 on a smooth boundary.
        assert_eq!(factor(0.3, 1.2, 0.6, 2.0), TABLE[0][0][3][0]);
        assert_eq!(factor(0.9, 1.45, 0.0, 25.0), 1.0);
        let half = factor(0.9, 1.45, 0.025, 25.0) - 1.0;
        assert!((half - (TABLE[1][1][0][4] - 1.0) * 0.5f64.powf(1.5)).abs() < 1e-12);
    }
}
