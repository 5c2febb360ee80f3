from scpformer.cache import cached_pickle


def test_second_call_loads_what_the_first_built(tmp_path, monkeypatch):
    monkeypatch.setenv("SCPFORMER_CACHE_DIR", str(tmp_path))
    calls = []

    def build():
        calls.append(1)
        return {"answer": 42}

    assert cached_pickle("thing", build) == {"answer": 42}
    assert cached_pickle("thing", build) == {"answer": 42}
    assert len(calls) == 1


def test_corrupt_cache_file_is_rebuilt_and_replaced(tmp_path, monkeypatch):
    monkeypatch.setenv("SCPFORMER_CACHE_DIR", str(tmp_path))
    cached_pickle("thing", lambda: [1, 2])
    (path,) = tmp_path.glob("thing-*.pkl")
    path.write_bytes(b"\x80\x05 truncated")
    assert cached_pickle("thing", lambda: [3]) == [3]
    assert cached_pickle("thing", lambda: [4]) == [3]


def test_changed_source_misses_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SCPFORMER_CACHE_DIR", str(tmp_path / "cache"))
    source = tmp_path / "module.py"
    source.write_text("A = 1\n")
    assert cached_pickle("thing", lambda: "old", source=str(source)) == "old"
    source.write_text("A = 2\n")
    assert cached_pickle("thing", lambda: "new", source=str(source)) == "new"


def test_empty_cache_dir_disables_caching(tmp_path, monkeypatch):
    monkeypatch.setenv("SCPFORMER_CACHE_DIR", "")
    calls = []
    cached_pickle("thing", lambda: calls.append(1))
    cached_pickle("thing", lambda: calls.append(1))
    assert len(calls) == 2


def test_a_cache_dir_that_is_a_file_is_a_miss_not_a_crash(tmp_path, monkeypatch):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("mine")
    monkeypatch.setenv("SCPFORMER_CACHE_DIR", str(blocker))
    assert cached_pickle("thing", lambda: [1]) == [1]
    assert cached_pickle("thing", lambda: [2]) == [2]
    assert blocker.read_text() == "mine"


def test_an_entry_that_unpickles_to_another_object_is_rebuilt(tmp_path, monkeypatch):
    import pickle

    monkeypatch.setenv("SCPFORMER_CACHE_DIR", str(tmp_path))
    cached_pickle("thing", lambda: [1, 2])
    (path,) = tmp_path.glob("thing-*.pkl")
    path.write_bytes(pickle.dumps({"not": "a compiled subproblem"}))
    assert cached_pickle("thing", lambda: [3]) == [3]
    assert cached_pickle("thing", lambda: [4]) == [3]
