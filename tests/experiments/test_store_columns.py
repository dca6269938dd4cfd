"""A results database whose tables lack columns is refused in one line naming them."""

import sqlite3

import pytest

from hptrack.experiments.store import SCHEMA_VERSION, ResultStore
from hptrack.interface import InputError


def test_a_table_with_missing_columns_is_one_line(tmp_path):
    path = tmp_path / "cut.db"
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE episodes (planner TEXT, n_targets INTEGER)")
    db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
    db.commit()
    db.close()
    with pytest.raises(InputError, match=r"table episodes has no column seed, ") as err:
        ResultStore(path)
    assert "\n" not in str(err.value)


def test_a_complete_database_opens(tmp_path):
    ResultStore(tmp_path / "new.db").close()
    ResultStore(tmp_path / "new.db").close()
