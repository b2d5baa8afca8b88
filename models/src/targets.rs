//! The targets of the paper's throwing problems (Section 5.2): the grid and the dartboard.
//!
//! Dartboard geometry (the paper gives only the 1.4 m diameter and the relative target-region
//! sizes): ring radii bull 0.058, inner single to 0.243, treble to 0.358, outer single to 0.583,
//! double to 0.700 m; 20 sectors of 18 degrees, sector k centred on the direction k * 18 degrees
//! counter-clockwise from +x. Each field is the quadrangle through its four corners (radii r1, r2
//! at the sector's two edges); the bull is the 20-gon the inner fields leave free, so the fields
//! tile the board. A field's centre (its context) is the polar midpoint (the board centre for the
//! bull). The target regions of the bull, inner and outer single fields are their polygons scaled
//! by 3.5 about the centre (every side 3.5x longer); trebles and doubles use the field itself.
//! This reproduces the paper's relative region sizes to within 1% (tested).

/// A point on the ground, in m.
pub type Point = [f64; 2];

/// The grid problem's 25 training targets: the 5 x 5 grid over [-5, -3]^2.
pub fn grid_training_targets() -> Vec<Vec<f64>> {
    grid(&[-3.0, -3.5, -4.0, -4.5, -5.0])
}

/// The grid problem's 16 test targets: the 4 x 4 grid over [-4.75, -3.25]^2.
pub fn grid_test_targets() -> Vec<Vec<f64>> {
    grid(&[-3.25, -3.75, -4.25, -4.75])
}

fn grid(ticks: &[f64]) -> Vec<Vec<f64>> {
    ticks
        .iter()
        .flat_map(|&x| ticks.iter().map(move |&y| vec![x, y]))
        .collect()
}

/// The grid problem's reward: minus the squared distance (m^2) from the target to the landing.
pub fn grid_reward(target: &[f64], landing: Point) -> f64 {
    -((target[0] - landing[0]).powi(2) + (target[1] - landing[1]).powi(2))
}

/// The five kinds of dartboard field.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Category {
    /// Bull and bull's eye, one field.
    Bull,
    /// The single fields between bull and treble ring.
    Inner,
    /// The treble ring.
    Treble,
    /// The single fields between treble and double ring.
    Outer,
    /// The double ring.
    Double,
}

impl Category {
    /// All categories, from the centre outwards.
    pub const ALL: [Category; 5] = [
        Category::Bull,
        Category::Inner,
        Category::Treble,
        Category::Outer,
        Category::Double,
    ];

    /// Lower-case name, as in summary.json.
    pub fn name(self) -> &'static str {
        match self {
            Category::Bull => "bull",
            Category::Inner => "inner",
            Category::Treble => "treble",
            Category::Outer => "outer",
            Category::Double => "double",
        }
    }
}

/// Ring radii (m): bull, inner single, treble, outer single, double.
pub const RING_RADII: [f64; 5] = [0.058, 0.243, 0.358, 0.583, 0.700];
/// Number of sectors.
pub const SECTORS: usize = 20;
/// How much the bull, inner and outer target regions are enlarged per side.
pub const REGION_SCALE: f64 = 3.5;
/// The reward outside the target region, and the scale of the reward inside it.
pub const MISS_REWARD: f64 = -10_000.0;

/// One dartboard field.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    /// Its kind.
    pub category: Category,
    /// Its sector, `None` for the bull.
    pub sector: Option<usize>,
    /// The context: the field's centre.
    pub centre: Point,
    /// The field itself (a convex polygon, counter-clockwise).
    pub field: Vec<Point>,
    /// The region in which the reward has a gradient (convex, counter-clockwise).
    pub region: Vec<Point>,
    /// The largest distance from the centre within the region (the paper's d_s).
    pub region_radius: f64,
}

impl Field {
    /// The paper's reward: -(10000 / d_s) ||s - b|| inside the target region, -10000 outside.
    pub fn reward(&self, landing: Point) -> f64 {
        if contains(&self.region, landing) {
            MISS_REWARD / self.region_radius * distance(self.centre, landing)
        } else {
            MISS_REWARD
        }
    }

    /// True when the landing lies in the field itself.
    pub fn hit(&self, landing: Point) -> bool {
        contains(&self.field, landing)
    }
}

/// The 81 fields of a dartboard centred at `centre`: the bull first, then for every sector the
/// inner single, treble, outer single and double field.
pub fn dartboard(centre: Point) -> Vec<Field> {
    let corner = |radius: f64, angle_deg: f64| {
        let a = angle_deg.to_radians();
        [centre[0] + radius * a.cos(), centre[1] + radius * a.sin()]
    };
    let half = 180.0 / SECTORS as f64;
    let bull: Vec<Point> = (0..SECTORS)
        .map(|k| corner(RING_RADII[0], k as f64 * 2.0 * half - half))
        .collect();
    let mut fields = vec![make_field(Category::Bull, None, centre, bull)];
    let rings = [Category::Inner, Category::Treble, Category::Outer, Category::Double];
    for sector in 0..SECTORS {
        let middle = sector as f64 * 2.0 * half;
        for (ring, category) in rings.into_iter().enumerate() {
            let (r1, r2) = (RING_RADII[ring], RING_RADII[ring + 1]);
            let polygon = vec![
                corner(r1, middle - half),
                corner(r2, middle - half),
                corner(r2, middle + half),
                corner(r1, middle + half),
            ];
            fields.push(make_field(
                category,
                Some(sector),
                corner((r1 + r2) / 2.0, middle),
                polygon,
            ));
        }
    }
    fields
}

fn make_field(category: Category, sector: Option<usize>, centre: Point, field: Vec<Point>) -> Field {
    let scale = match category {
        Category::Bull | Category::Inner | Category::Outer => REGION_SCALE,
        Category::Treble | Category::Double => 1.0,
    };
    let region: Vec<Point> = field
        .iter()
        .map(|p| {
            [
                centre[0] + scale * (p[0] - centre[0]),
                centre[1] + scale * (p[1] - centre[1]),
            ]
        })
        .collect();
    // A convex polygon's farthest point from any interior point is a vertex.
    let region_radius = region.iter().map(|&p| distance(centre, p)).fold(0.0, f64::max);
    Field {
        category,
        sector,
        centre,
        field,
        region,
        region_radius,
    }
}

/// Euclidean distance.
pub fn distance(a: Point, b: Point) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// Whether `p` lies in the convex counter-clockwise polygon (boundary included).
pub fn contains(polygon: &[Point], p: Point) -> bool {
    polygon
        .iter()
        .zip(polygon.iter().cycle().skip(1))
        .all(|(a, b)| (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) >= 0.0)
}

/// Area of a simple polygon (shoelace).
pub fn area(polygon: &[Point]) -> f64 {
    polygon
        .iter()
        .zip(polygon.iter().cycle().skip(1))
        .map(|(a, b)| a[0] * b[1] - b[0] * a[1])
        .sum::<f64>()
        .abs()
        / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    const CENTRE: Point = [-3.55, -3.55];

    #[test]
    fn grids_match_the_paper() {
        let train = grid_training_targets();
        let test = grid_test_targets();
        assert_eq!((train.len(), test.len()), (25, 16));
        assert!(train.contains(&vec![-3.0, -5.0]) && train.contains(&vec![-4.5, -3.5]));
        assert!(test.contains(&vec![-3.25, -4.75]));
        assert!((grid_reward(&[-3.0, -4.0], [-3.3, -3.6]) + 0.25).abs() < 1e-12);
    }

    #[test]
    fn eighty_one_fields_tile_the_board() {
        let fields = dartboard(CENTRE);
        assert_eq!(fields.len(), 81);
        for category in Category::ALL {
            let count = fields.iter().filter(|f| f.category == category).count();
            assert_eq!(count, if category == Category::Bull { 1 } else { 20 });
        }
        // Every point of the board lies in exactly one field (up to boundaries, which random
        // points miss); points off the board lie in none.
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        for _ in 0..20_000 {
            let p = [
                CENTRE[0] + rng.random_range(-0.72..0.72),
                CENTRE[1] + rng.random_range(-0.72..0.72),
            ];
            let inside = fields.iter().filter(|f| f.hit(p)).count();
            let r = distance(p, CENTRE);
            // The outer boundary is a 20-gon inscribed in the 0.7 m circle.
            let on_board = r < 0.7 * (9f64.to_radians()).cos();
            if on_board {
                assert_eq!(inside, 1, "{p:?} at r = {r}");
            } else if r > 0.7 {
                assert_eq!(inside, 0, "{p:?}");
            }
        }
        // Centres lie in their own fields.
        assert!(fields.iter().all(|f| f.hit(f.centre)));
    }

    #[test]
    fn target_region_sizes_match_the_paper() {
        let fields = dartboard(CENTRE);
        let region = |c: Category| area(&fields.iter().find(|f| f.category == c).unwrap().region);
        let treble = region(Category::Treble);
        // Paper Fig. 10 legend: treble 1.00, double 2.17, inner 9.88, bull 12.04, outer 37.67.
        for (category, paper) in [
            (Category::Double, 2.17),
            (Category::Inner, 9.88),
            (Category::Bull, 12.04),
            (Category::Outer, 37.67),
        ] {
            let ratio = region(category) / treble;
            assert!((ratio / paper - 1.0).abs() < 0.01, "{category:?}: {ratio} vs {paper}");
        }
    }

    #[test]
    fn rewards_follow_the_paper() {
        let fields = dartboard(CENTRE);
        let treble = &fields[2];
        assert_eq!(treble.category, Category::Treble);
        assert_eq!(treble.reward(treble.centre), 0.0);
        // At the region's farthest vertex (nudged inside) the reward approaches -10000.
        let vertex = treble.region[1];
        let inside = [
            0.999 * vertex[0] + 0.001 * treble.centre[0],
            0.999 * vertex[1] + 0.001 * treble.centre[1],
        ];
        let expected = MISS_REWARD * distance(treble.centre, inside) / treble.region_radius;
        assert!((treble.reward(inside) - expected).abs() < 1e-9);
        assert!(treble.reward(inside) > MISS_REWARD && treble.reward(inside) < -9_000.0);
        assert_eq!(treble.reward(CENTRE), MISS_REWARD);
        // The enlarged inner-single region reaches the bull: a landing on the board centre is
        // rewarded for the inner fields but does not hit them.
        let inner = &fields[1];
        assert_eq!(inner.category, Category::Inner);
        assert!(inner.reward(CENTRE) > MISS_REWARD && !inner.hit(CENTRE));
        assert!(fields[0].hit(CENTRE) && fields[0].reward(CENTRE) == 0.0);
    }
}
