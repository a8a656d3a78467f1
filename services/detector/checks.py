"""Candidate checks: the judgement of step 6 that makes a measured circle (``measure.py``) a
ball or not.

A ball's disc is mostly mask (fill), its rim is a mask edge over most of its visible length
(edge support), and the more mask lies just around it (leak, outside), the more rim support
it needs, so a round patch of a large yellow-green area (sunlit trees) fails; the blob is
vivid enough (colourfulness); in very dark frames the mean colour of the disc must have the
target's hue too; and its edge is even all round (a box's corners are not).
"""

from dataclasses import dataclass

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.measure import ColourMetrics, MaskMetrics

# Below this chroma (raw units) single pixels' hues are rounding noise, so the hue of the
# candidate's mean colour is checked as well.
LOW_CHROMA = 6.0
# A candidate with a spread of its edge distance above CORNER_SPREAD (a square's is ~0.1, a
# ball's mostly below 0.06 and at most 0.11 on the real dev photos) that also leaks past its
# rim in CORNER_RUNS or more separate places (corners) is a polygon, not a ball; a ball's
# mask leaks in one or two (a touching neighbour, its shadow, a smear of motion blur).
CORNER_SPREAD = 0.07
CORNER_LEAK = 0.08
CORNER_RUNS = 3
# A candidate that is plainly a ball by shape (clean, an edge this even, at least
# SURE_SIZE times small_radius for the evenness to mean something) needs only its colour in
# the hue range, not hue_margin inside it: a ball under a warm lamp is yellower than felt in
# daylight. It needs only SURE_COLOURFULNESS of min_colourfulness too: a ball in dim light
# beside a lamp or a lit screen is dull next to the frame's bright level. Or it may be vivid
# only next to its own lit side (see ColourMetrics.lit_colourfulness).
SURE_SPREAD = 0.05
SURE_SIZE = 2.0
SURE_COLOURFULNESS = 0.75


@dataclass(frozen=True)
class CandidateMetrics:
    """Everything a candidate circle is judged on."""

    mask: MaskMetrics
    colour: ColourMetrics
    size: float               # radius over small_radius: below 1, a small ball
    dark_side: bool = False   # accepted by the dark-side second look (dark.py)
    highlighted: bool = False  # measured with its washed-out highlight (highlight.py)
    partly_hidden: bool = False  # measured on its part in view (occlusion.py)
    # share of its rim that is a brightness edge on the frame, for a ball in front of another
    # (front.py); 0 for every other candidate
    front_edges: float = 0.0

    @property
    def clean(self) -> bool:
        """One isolated round blob: nothing around it, a crisp rim, a full disc."""
        return (self.mask.leak <= 0.05 and self.mask.outside <= 0.05
                and self.mask.support >= 0.8 and self.mask.fill >= 0.85)


def hue_in_range(hue: float, config: DetectorConfig, margin: float = -0.5) -> bool:
    """Whether a hue is within the configured range, at least ``margin`` inside it (the default:
    half a unit of slack; wraps through 0)."""
    low, high = config.h_min + margin, config.h_max - margin
    if low <= high:
        return low <= hue <= high
    return hue >= low or hue <= high


def _bounds(metrics: CandidateMetrics, config: DetectorConfig) -> tuple[float, float, float, bool, float]:
    """What ``judge`` and ``failed_checks`` read: the clutter around the rim, the rim's edge
    support, the mask outside it, whether the candidate is plainly a ball by shape, and its
    colourfulness floor."""
    on_mask = metrics.mask
    clutter = on_mask.leak + on_mask.outside
    support, outside = on_mask.support, on_mask.outside
    if metrics.front_edges:
        # A ball in front of another (front.py): the colour going on past its rim is the
        # ball behind it, and its rim is an edge on the frame instead of the mask.
        clutter, support, outside = 0.0, metrics.front_edges, 0.0
    # (size before spread: the spread is measured only when read, see MaskMetrics)
    sure_by_shape = metrics.clean and metrics.size >= SURE_SIZE and on_mask.spread <= SURE_SPREAD
    colourfulness_floor = config.min_colourfulness * (SURE_COLOURFULNESS if sure_by_shape else 1.0)
    return clutter, support, outside, sure_by_shape, colourfulness_floor


def judge(metrics: CandidateMetrics, config: DetectorConfig) -> float | None:
    """Score in [0, 1] of a measured circle, or None when a check fails.

    The more mask lies around the circle (leak, outside), the more of its rim must be a
    clean edge: a ball touching another keeps most of its rim, a round patch cut out of a
    large yellow-green area (sunlit trees) does not.
    """
    on_mask, colour = metrics.mask, metrics.colour
    clutter, support, outside, sure_by_shape, colourfulness_floor = _bounds(metrics, config)
    vivid = (colour.colourfulness >= colourfulness_floor
             or (sure_by_shape and colour.lit_colourfulness >= config.min_colourfulness))
    # A circle cut by the frame edge must still show as much rim as a whole ball of
    # small_radius has: a few pixels of arc at the border prove nothing. A ball smaller
    # than that must be whole, and have its outline found (see BallDetector._outlines).
    if (on_mask.visible < max(config.min_visible_fraction, min(1.0, 1.0 / metrics.size))
            or on_mask.fill < config.min_fill_ratio
            or support < config.min_edge_support + clutter
            or outside > config.max_outside_ratio
            or not vivid):
        return None
    if colour.mean_chroma < LOW_CHROMA and not hue_in_range(colour.mean_hue, config):
        return None
    # (the mask pixels' mean: a two-colour ball's other half does not count)
    if (config.hue_margin > 0 and not sure_by_shape
            and not hue_in_range(colour.colour_hue, config, config.hue_margin - 0.5)):
        return None
    # Corners: the edge's distance from the centre varies and the blob pokes out of the
    # circle in several places (a box face); a ball's edge is even, its neighbours add no
    # spread, and what leaks past its rim does so in one or two places.
    # (Not with a joined highlight: glints of bright ground poke out of it too, and white
    # areas around a candidate already fail its leak and outside checks.)
    # (leak before spread: the spread is measured only when read)
    # (Nor for a ball in front of another: the ball behind leaks past its rim, and the frame's
    # edge already follows its circle all round, which a box's corners do not.)
    if (not metrics.highlighted and not metrics.front_edges and on_mask.leak > CORNER_LEAK and on_mask.leak_runs >= CORNER_RUNS
            and on_mask.spread > CORNER_SPREAD):
        return None
    score = (on_mask.fill + support - clutter) / 2.0
    score = max(0.0, min(1.0, score))
    if score < config.min_score:
        return None
    return score


def failed_checks(metrics: CandidateMetrics, config: DetectorConfig) -> list[str]:
    """Why ``judge`` rejects a measured circle: one phrase per check it fails, with the value
    and the bound ([] when it passes). Every check is evaluated, not only the first that
    fails, so that one look shows all a candidate lacks (``balltrack detect --explain``,
    ``real_photos --misses``). Mirrors ``judge`` check for check (a property test holds them
    together); judge stays the fast path."""
    on_mask, colour = metrics.mask, metrics.colour
    clutter, support, outside, sure_by_shape, colourfulness_floor = _bounds(metrics, config)
    failed = []
    visible_floor = max(config.min_visible_fraction, min(1.0, 1.0 / metrics.size))
    if on_mask.visible < visible_floor:
        failed.append(f"rim in view {on_mask.visible:.2f} < {visible_floor:.2f}")
    if on_mask.fill < config.min_fill_ratio:
        failed.append(f"fill {on_mask.fill:.2f} < min_fill_ratio {config.min_fill_ratio:.2f}")
    if support < config.min_edge_support + clutter:
        failed.append(f"edge support {support:.2f} < {config.min_edge_support + clutter:.2f} "
                      f"(min_edge_support plus the mask around the rim, {clutter:.2f})")
    if outside > config.max_outside_ratio:
        failed.append(f"mask around it {outside:.2f} > max_outside_ratio {config.max_outside_ratio:.2f}")
    if not (colour.colourfulness >= colourfulness_floor
            or (sure_by_shape and colour.lit_colourfulness >= config.min_colourfulness)):
        failed.append(f"colourfulness {colour.colourfulness:.2f} < {colourfulness_floor:.2f} "
                      "(mean chroma over the frame's bright level)")
    if colour.mean_chroma < LOW_CHROMA and not hue_in_range(colour.mean_hue, config):
        failed.append(f"a dim disc (mean chroma {colour.mean_chroma:.1f} < {LOW_CHROMA:g}) whose mean "
                      f"colour's hue {colour.mean_hue:.1f} is outside h_min-h_max")
    if (config.hue_margin > 0 and not sure_by_shape
            and not hue_in_range(colour.colour_hue, config, config.hue_margin - 0.5)):
        failed.append(f"hue of its colour pixels' mean {colour.colour_hue:.1f} is not hue_margin "
                      f"({config.hue_margin:g}) inside h_min-h_max ({config.h_min}-{config.h_max})")
    if (not metrics.highlighted and not metrics.front_edges and on_mask.leak > CORNER_LEAK
            and on_mask.leak_runs >= CORNER_RUNS and on_mask.spread > CORNER_SPREAD):
        failed.append(f"corners: the mask goes on past its rim in {on_mask.leak_runs} places and its "
                      f"edge is uneven (spread {on_mask.spread:.3f} > {CORNER_SPREAD:g})")
    score = max(0.0, min(1.0, (on_mask.fill + support - clutter) / 2.0))
    if score < config.min_score:
        failed.append(f"score {score:.2f} < min_score {config.min_score:.2f}")
    return failed
