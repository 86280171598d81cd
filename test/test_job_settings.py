"""The job's settings from the automation config: the mode, the heights, the pair margin."""
import pytest

from scara_collab.core.config import load_config
from scara_collab.core.job_settings import JobSettings, MODES
from scara_collab.core.sorting import pick_height


def test_settings_come_from_the_config_with_the_mode_overridden(cell):
    """Every mode is accepted; another one is refused, naming the choices."""
    cfg = load_config('automation')
    assert JobSettings.from_config(cell, cfg).mode == cfg['mode']
    for mode in MODES:
        assert JobSettings.from_config(cell, cfg, mode).mode == mode
    with pytest.raises(ValueError, match='mode must be one of'):
        JobSettings.from_config(cell, cfg, 'solo')


def test_a_lifted_item_clears_the_items_on_the_belt_by_the_carry_clearance(cell):
    """``carry_z``: the pick height plus the item and the clearance; no lift: the pick height."""
    cfg = load_config('automation')
    controllers = dict(load_config('controllers'), planning_buffer=0.05)
    s = JobSettings.from_config(cell, dict(cfg, lift_after_grasp=True), controllers=controllers)
    assert s.pick_z == pytest.approx(pick_height(cell, cfg['pick_clearance']))
    assert s.carry_z - s.pick_z == pytest.approx(cell.item_size + cfg['carry_clearance'])
    assert s.pair_margin == pytest.approx(cell.safety_margin + 0.05)
    flat = JobSettings.from_config(cell, dict(cfg, lift_after_grasp=False))
    assert flat.carry_z == flat.pick_z
