"""Terrain: the generators' shapes, the spec, the grid -> MuJoCo hfield mapping (checked with MuJoCo C's own
rays and PNG reader), and the exported MJCF reloading the same heights."""

import mujoco
import numpy as np
import pytest

from hopper_mjx import model, registry, terrain
from hopper_mjx.model import __main__ as model_main
from hopper_mjx.terrain import generators
from hopper_mjx.terrain.spec import KEYS

SPECS = {  # one of each generator but flat and heightmap
    "rough": "rough:amp=0.03,wavelength=0.4,seed=1",
    "steps": "steps:height=0.05,depth=0.5,x=0.5",
    "stairs": "stairs:height=0.04,depth=0.25,n=3,x=0.3",
    "gaps": "gaps:width=0.12,spacing=0.5,depth=0.2,x=0.5",
    "obstacle": "obstacle:height=0.15,x=0.6",
    "crater": "crater:radius=0.5,depth=0.1,rim=0.03,x=1",
    "course": "course:levels=2,tile=2.5,seed=1,cell=0.05",
}


def ray_heights(mj_model, xy):
    """MuJoCo C's surface height at each (x, y): a ray cast straight down onto the floor."""
    d = mujoco.MjData(mj_model)
    d.qpos[2] = 100.0  # the robot out of the rays' way
    mujoco.mj_forward(mj_model, d)
    geom = np.zeros(1, np.int32)
    out = []
    for x, y in xy:
        dist = mujoco.mj_ray(mj_model, d, np.array([x, y, 5.0]), np.array([0.0, 0.0, -1.0]), None, 1, -1, geom)
        assert dist >= 0 and mj_model.geom(int(geom[0])).name == model.FLOOR_GEOM
        out.append(5.0 - dist)
    return np.array(out)


def test_every_registered_generator_has_its_keys():
    assert list(KEYS) == list(registry.TERRAINS) and set(SPECS) | {"flat", "heightmap"} == set(KEYS)


def test_rough_is_zero_mean_peaks_at_amp_and_follows_its_seed():
    t = terrain.parse(SPECS["rough"]).terrain()
    assert abs(t.heights.mean()) < 1e-12 and np.abs(t.heights).max() == pytest.approx(0.03, rel=1e-12)
    again = terrain.parse(SPECS["rough"]).terrain()
    other = terrain.parse("rough:amp=0.03,wavelength=0.4,seed=2").terrain()
    assert np.array_equal(t.heights, again.heights) and np.abs(t.heights - other.heights).max() > 0.01
    # The wavelength sets the slope: peak |dh/dx| ~ 2 pi amp / wavelength, within the waves' spread.
    x, _ = t.axes()
    slope = np.abs(np.diff(t.heights, axis=1)).max() / (x[1] - x[0])
    assert 0.3 * 2 * np.pi * 0.03 / 0.4 < slope < 3 * 2 * np.pi * 0.03 / 0.4


def test_shapes_sit_where_their_keys_put_them():
    def height_at(spec, x, y=0.0):
        t = terrain.parse(spec).terrain()
        xs, ys = t.axes()
        return t.heights[np.argmin(abs(ys - y)), np.argmin(abs(xs - x))]

    for x, h in ((0.0, 0), (0.48, 0), (0.52, 0.05), (0.96, 0.05), (1.04, 0)):
        assert height_at(SPECS["steps"], x) == pytest.approx(h)
    # stairs: 3 risers of 0.04 m up every 0.25 m from 0.3, the top tread and a landing as long, 3 down.
    for x, h in ((0.2, 0), (0.4, 0.04), (0.6, 0.08), (1.0, 0.12), (1.2, 0.12), (1.4, 0.08), (1.6, 0.04), (1.88, 0)):
        assert height_at(SPECS["stairs"], x) == pytest.approx(h, abs=1e-12), x
    for x, h in ((0.52, -0.2), (0.6, -0.2), (0.68, 0.0), (1.04, -0.2), (0.4, 0.0)):
        assert height_at(SPECS["gaps"], x) == pytest.approx(h), x
    for x, h in ((0.56, 0), (0.64, 0.15), (0.68, 0.15), (0.72, 0)):
        assert height_at(SPECS["obstacle"], x, y=1.7) == pytest.approx(h), x
    assert height_at(SPECS["crater"], 1.0) == pytest.approx(-0.1 + 0.03 * np.exp(-16))
    assert height_at(SPECS["crater"], 1.0, 0.52) == pytest.approx(0.03 * np.exp(-0.16**2))  # the rim, r = 1.04 R
    assert height_at(SPECS["crater"], -1.0) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("name", list(SPECS))
def test_mujoco_places_every_vertex_at_its_height(name):
    """The hfield mapping: MuJoCo C's surface, probed by rays at vertices, is the grid's heights
    (to the float32 of MuJoCo's hfield_data: 2^-24 of the height range)."""
    t = terrain.parse(SPECS[name]).terrain()
    m = model.load(terrain=t)
    assert m.geom(model.FLOOR_GEOM).type[0] == mujoco.mjtGeom.mjGEOM_HFIELD
    assert m.pair_geom1.tolist().count(m.geom(model.FLOOR_GEOM).id) == m.npair  # every pair kept
    span = np.ptp(t.heights)
    np.testing.assert_allclose(terrain.from_model(m).heights, t.heights, rtol=0, atol=span * 2**-23)
    xs, ys = t.axes()
    rng = np.random.default_rng(0)
    r, c = rng.integers(1, t.shape[0] - 1, 40), rng.integers(1, t.shape[1] - 1, 40)
    np.testing.assert_allclose(ray_heights(m, np.stack([xs[c], ys[r]], 1)), t.heights[r, c], rtol=0,
                               atol=span * 2**-22 + 1e-12)


def test_a_level_grid_is_an_hfield_mujoco_accepts():
    t = terrain.Terrain(np.full((5, 6), 0.07), (1.0, 1.0))
    f = terrain.hfield(t)
    assert f.size[2] == terrain.FLAT_SPAN and f.z == 0.07 and not f.data.any()
    m = model.load(terrain=t)
    np.testing.assert_allclose(ray_heights(m, [(0.3, -0.2), (-0.9, 0.9)]), 0.07, atol=1e-12)


def test_export_reloads_the_same_model_in_mujoco(tmp_path, capsys):
    ground = terrain.parse(SPECS["rough"])
    path = tmp_path / "m.xml"
    assert model_main.main(["--export", str(path), "--terrain", SPECS["rough"]]) == 0
    assert "m_terrain.bin" in capsys.readouterr().out and (tmp_path / "m_terrain.bin").is_file()
    compiled, reloaded = model.load(terrain=ground.terrain()), mujoco.MjModel.from_xml_path(str(path))
    for field in ("hfield_data", "hfield_size", "geom_pos", "geom_type", "pair_geom1", "pair_geom2", "pair_dim"):
        assert np.array_equal(getattr(compiled, field), getattr(reloaded, field)), field
    d = mujoco.MjData(reloaded)
    from hopper_mjx.model.robot import stance_qpos

    d.qpos[:] = stance_qpos(reloaded)
    mujoco.mj_step(reloaded, d, 300)  # it steps: the foot lands on the hfield and holds
    assert d.ncon > 0 and np.isfinite(d.qpos).all() and 0.4 < d.qpos[2] < 0.9


def test_flat_keeps_the_plane_and_its_export():
    assert terrain.parse("flat").terrain() is None and str(terrain.parse("flat")) == "flat"
    assert model.load(terrain=None).geom(model.FLOOR_GEOM).type[0] == mujoco.mjtGeom.mjGEOM_PLANE


def test_heightmap_is_laid_out_as_mujoco_reads_a_png(tmp_path):
    import imageio.v3 as iio

    image = np.random.default_rng(3).integers(0, 256, (7, 9)).astype(np.uint8)
    image[0, 0], image[-1, -1] = 0, 255
    iio.imwrite(tmp_path / "g.png", image)
    t = terrain.parse(f"heightmap:{tmp_path / 'g.png'},size=4x3,height=0.3").terrain()
    assert t.size == (2.0, 1.5) and t.shape == (7, 9)
    np.testing.assert_allclose(t.heights, 0.3 * image[::-1] / 255.0)  # black 0, white 0.3 m, top row at +y
    spec = mujoco.MjSpec()
    spec.add_hfield(name="png", file=str(tmp_path / "g.png"), size=[2, 1.5, 0.3, 0.1])
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname="png")
    ours = terrain.hfield(t).data
    np.testing.assert_allclose(ours, spec.compile().hfield_data, atol=1e-6)  # MuJoCo's own PNG reading


@pytest.mark.parametrize("text, message", [
    ("hills", "unknown terrain 'hills'; choose from: flat, rough,"),
    ("rough:amp=0.03,bumpiness=2", "rough has no key 'bumpiness'; it takes amp, wavelength, seed, size, cell"),
    ("rough:amp=nan", "amp=nan must be finite"),
    ("rough:wavelength=0", "wavelength=0 must be > 0 m"),
    ("obstacle:height=-0.1", "height=-0.1 must be >= 0 m"),
    ("rough:seed=1.5", "seed=1.5 must be a whole number"),
    ("rough:size=4xabc", "size=abc is not a number"),
    ("steps:cell=5", "cell=5 m is larger than the grid's extent 4 m"),
    ("gaps:width=0.5,spacing=0.4", "width=0.5 must be less than spacing=0.4"),
    ("flat:amp=1", "flat has no key 'amp'; it takes none"),
    ("heightmap:size=4x4", "heightmap needs a PNG file"),
    ("steps:cell=0.04,cell=0.04", "cell is given twice"),
    ("rough:seed=1,seed=2", "seed is given twice"),
    ("rough:amp", "'amp' is not key=value; rough takes amp, wavelength, seed, size, cell"),
    ("course:size=4", "course has no key 'size'; it takes levels, tile, amp, step, gap, block, seed, cell"),
    ("course:tile=1.5", "course: tile=1.5 m is too small; a tile needs at least 2 m"),
    # The widest trench must fit its tile (here 0.2 m between the pad's ramp and the edge) and its spacing.
    ("course:tile=2", "course: gap=0.3 m must be less than 0.2 m"),
    ("course:gap=0.9", "course: gap=0.9 m must be less than 0.8 m"),
    ("course:cell=0.3", "course: cell=0.3 m cannot hold its rough ground's 0.4 m waves; at most 0.2 m"),
])
def test_bad_specs_are_one_line(text, message):
    with pytest.raises(terrain.TerrainError, match=None) as err:
        terrain.parse(text)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_generators_are_pure_functions_of_the_vertices():
    x, y = terrain.vertices((1.0, 0.5), (11, 21))
    assert x.shape == (11, 21) and x[0, 0] == -1.0 and y[-1, 0] == 0.5 and x[0, -1] == 1.0
    assert not generators.flat(x, y).any()


def test_auto_steps_a_terrain_with_the_chain_engine(capsys):
    from hopper_mjx import engine
    from hopper_mjx.engine import chain

    m = model.load(terrain=terrain.parse("steps").terrain())
    auto = engine.make("auto", m)
    assert auto.name == "chain" and capsys.readouterr().err == ""
    assert auto.chain.terrain.max_contacts == chain.FOOT_CONTACTS and len(auto.chain.terrain.boxes) == 3  # base, legs


def test_seed_each_draws_every_instance_its_own_ground():
    each = terrain.parse("rough:amp=0.02,seed=each,size=1x1,cell=0.1")
    assert str(each) == "rough:amp=0.02,wavelength=0.4,seed=each,size=1x1,cell=0.1"
    assert terrain.parse(str(each)) == each
    grids = each.grids(7, range(3))
    assert grids.shape == (3, 11, 11)
    assert np.abs(grids[0] - grids[1]).max() > 1e-3  # their own draws
    np.testing.assert_array_equal(grids, each.grids(7, range(3)))  # deterministic
    np.testing.assert_allclose(np.abs(grids).max(axis=(1, 2)), 0.02)  # each scaled to the amplitude
    np.testing.assert_array_equal(each.terrain().heights, each.grids(0, [0])[0])  # the model: seed 0, instance 0
    fixed = terrain.parse("rough:amp=0.02,seed=3,size=1x1,cell=0.1")
    assert fixed.grids(7, range(3)) is None and fixed.instance(7, 2) is fixed  # one ground for all


def test_obstacles_are_the_bands_to_get_over():
    np.testing.assert_allclose(terrain.parse("obstacle:height=0.1,x=0.6,length=0.2").obstacles(), [[0.6, 0.8, 0.1]])
    np.testing.assert_allclose(terrain.parse("steps:height=0.05,depth=1,x=1").obstacles(), [[1, 2, 0.05]])
    np.testing.assert_allclose(terrain.parse("stairs:height=0.05,depth=0.3,n=2,x=0.5").obstacles(),
                               [[0.5, 2.0, 0.1]])
    np.testing.assert_allclose(terrain.parse("gaps:width=0.1,spacing=0.5,depth=0.2,x=0.5,size=3").obstacles(),
                               [[0.5, 0.6, -0.2], [1.0, 1.1, -0.2]])
    assert terrain.parse("rough").obstacles().shape == (0, 3)


def test_an_instances_own_ground_goes_into_mjxs_height_field_as_mujoco_reads_it():
    """The MJX engine's `on_ground` (through `terrain.to_model_data`): the data it writes, put back into the
    compiled model, is the instance's heights as MuJoCo C's own hfield reads them (rows along +y, in the model's
    elevation range)."""
    from hopper_mjx.engine.mjx import MjxEngine

    m = model.load(terrain=terrain.parse("rough:amp=0.02,seed=1,size=1x0.6,cell=0.1").terrain())
    other = terrain.parse("obstacle:height=0.05,x=0.2,size=1x0.6,cell=0.1").terrain().heights  # another ground
    engine = MjxEngine(m)
    data = np.asarray(engine.on_ground(engine.model, other).hfield_data)
    m.hfield_data[:] = data
    np.testing.assert_allclose(terrain.from_model(m).heights, other, atol=1e-7)


def test_the_course_lays_out_its_levels_and_kinds_as_tiles():
    """The training course: a tile per level (row) and kind (column), each with a flat pad at its centre and flat
    ground at its edge, in a flat border a tile wide; each kind's ground grows with the level as level / (levels - 1)
    of the hardest, from flat at level 0."""
    from hopper_mjx.terrain import spec

    ground = terrain.parse("course:levels=4,tile=4,amp=0.04,step=0.08,gap=0.3,block=0.15,seed=2")
    assert ground.size == (24.0, 24.0) and terrain.parse(str(ground)) == ground
    t = ground.terrain()
    xs, ys = t.axes()
    border = (np.abs(xs)[None, :] > 8.0) | (np.abs(ys)[:, None] > 8.0)
    assert border.mean() > 0.5 and np.abs(t.heights[border]).max() == 0.0
    centres = spec.tile_centres(ground)
    assert centres.shape == (4, 4, 2) and tuple(centres[0, 0]) == (-6.0, -6.0)

    def tile(level, kind):
        (cx, cy), half = centres[level, kind], 2.0
        inside_x, inside_y = np.abs(xs - cx) < half - 1e-9, np.abs(ys - cy) < half - 1e-9
        ring = np.maximum(np.abs(xs - cx)[None, :], np.abs(ys - cy)[:, None])[np.ix_(inside_y, inside_x)]
        return t.heights[np.ix_(inside_y, inside_x)], ring

    for level in range(4):
        share = level / 3
        for kind, name in enumerate(generators.COURSE_KINDS):
            h, ring = tile(level, kind)
            if level == 0:
                assert np.abs(h).max() == 0.0, name
                continue
            assert np.abs(h[ring < generators.COURSE_PAD - 1e-9]).max() == 0.0, (level, name)  # the pad
            assert np.abs(h[ring > 2.0 - generators.COURSE_EDGE + 0.01]).max() == 0.0, (level, name)  # the edge
            hardest = {"rough": 0.04 * share, "steps": 0.08 * share * 2, "gaps": -0.2, "blocks": 0.15 * share}[name]
            if name == "rough":  # its peak is the whole grid's: a tile's is near it, never over
                assert 0.7 * hardest < np.abs(h).max() <= hardest + 1e-12, level
            else:
                assert (h.min() if hardest < 0 else h.max()) == pytest.approx(hardest, rel=1e-9), (level, name)
        # The gaps' trenches widen with the level: the deep vertices along a line out from the centre.
        h, ring = tile(level, 2)
        row = h[h.shape[0] // 2]
        assert (row < 0).sum() * 0.04 == pytest.approx(4 * 0.3 * share, abs=4 * 0.04 + 1e-9), level


def test_the_map_draws_a_terrain_from_above_and_refuses_the_plane(tmp_path, capsys):
    """`python -m hopper_mjx.model --map`: a PNG of the heights; the flat plane or a name not .png is one line."""
    import imageio.v3 as iio

    path = tmp_path / "course.png"
    assert model_main.main(["--map", str(path), "--terrain", "course:levels=2,tile=2,gap=0.15,cell=0.1"]) == 0
    image = iio.imread(path)
    assert image.ndim == 3 and image.shape[0] > 400 and image[..., :3].std() > 10  # drawn, not blank
    assert model_main.main(["--map", str(tmp_path / "flat.png")]) == 2
    assert model_main.main(["--map", str(tmp_path / "x.txt"), "--terrain", "rough"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "the flat plane has none" in err[0] and ".png" in err[1]
    assert not (tmp_path / "flat.png").exists() and not (tmp_path / "x.txt").exists()


@pytest.mark.parametrize("size", ["4x4", "12x4", "24x24", "7.2x3.6"])
def test_a_features_edges_take_the_same_vertices_on_every_ground_size(size):
    """A block from x = 0.6 m, 0.1 m long, on 4 cm cells holds the vertices at 0.60, 0.64 and 0.68 m whatever the
    ground's extent: where the grid lines were left a rounding off their decimal values, a 24 m ground's vertex at
    0.6 m fell outside the block, whose top was then half as long as on a 12 m one."""
    t = terrain.parse(f"obstacle:height=0.1,x=0.6,length=0.1,size={size}").terrain()
    xs, _ = t.axes()
    row = t.heights[t.heights.shape[0] // 2]
    np.testing.assert_allclose(xs[row > 0], [0.6, 0.64, 0.68], atol=1e-12)
    steps = terrain.parse(f"steps:height=0.05,depth=0.5,x=0.6,size={size}").terrain()
    assert steps.axes()[0][steps.heights[0] > 0].min() == pytest.approx(0.6, abs=1e-12)  # its riser, likewise
