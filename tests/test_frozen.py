"""The heap frozen over timed frames (experiments.frozen): counted, never timed."""

import gc

from experiments.frozen import frozen_heap


def test_the_heap_is_frozen_inside_the_block_and_unfrozen_after():
    before = gc.get_freeze_count()
    with frozen_heap():
        assert gc.get_freeze_count() > before
    assert gc.get_freeze_count() == before == 0
