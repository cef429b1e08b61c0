"""A store's journal: staged files reach the store all at once or not at all, whatever step a crash interrupts."""

import pytest

import hybrid.terrain.store_journal as journal


def _store(tmp_path):
    root = tmp_path / "s"
    (root / "a" / "c").mkdir(parents=True)
    for key in ("a/c/0", "a/c/1", "manifest.json", "zarr.json"):
        (root / key).write_text(f"old {key}")
    return root


def _state(root):
    texts = {(root / k).read_text().split()[0] for k in ("a/c/0", "a/c/1", "manifest.json", "zarr.json")}
    assert len(texts) == 1, texts  # never a mixture
    return texts.pop()


def _change(root):
    tx = journal.Transaction(root)
    for key in ("a/c/1", "a/c/0", "a/c/2/new", "zarr.json", "manifest.json"):
        tx.add(key, f"new {key}".encode())
    return tx


@pytest.mark.parametrize(
    ("where", "count", "state"),
    [
        ("_write", 2, "old"),
        ("_write", 5, "old"),
        ("_move", 0, "old"),
        ("_move", 1, "new"),
        ("_move", 3, "new"),
        ("_move", 5, "new"),
    ],
)
def test_a_crash_at_any_step_leaves_all_old_or_all_new_after_recovery(tmp_path, monkeypatch, where, count, state):
    root = _store(tmp_path)
    real, calls = getattr(journal, where), []

    def crash(*args):
        calls.append(args)
        if len(calls) > count:
            raise OSError("simulated crash")
        return real(*args)

    monkeypatch.setattr(journal, where, crash)
    with pytest.raises(OSError):
        _change(root).commit()
    monkeypatch.setattr(journal, where, real)
    assert journal.recover(root) in ("finished", "dropped")
    assert _state(root) == state and (root / "a/c/2/new").exists() == (state == "new")
    assert not (root / journal.EDIT_DIR).exists() and journal.recover(root) is None


def test_a_commit_replaces_every_file_and_an_abort_none(tmp_path, monkeypatch):
    root = _store(tmp_path)
    tx = _change(root)
    tx.abort()
    assert _state(root) == "old" and journal.recover(root) == "dropped"
    order, real = [], journal._move

    def move(src, dst):
        order.append(dst.relative_to(root).as_posix())
        real(src, dst)

    monkeypatch.setattr(journal, "_move", move)
    _change(root).commit()
    assert _state(root) == "new" and order[-2:] == ["manifest.json", "zarr.json"]  # the header last
