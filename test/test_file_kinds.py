"""
A file parameter given a file of the wrong kind: one line naming the file and what it is.

``model_file:=/etc/passwd`` once ended in numpy's ``allow_pickle`` message; an .npy array or an
empty file in a traceback; an archive of Python objects would have been refused only by
numpy's wording. Nothing is ever unpickled.
"""
import os
from pathlib import Path
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from fixtures.demo_model import demo_model
from pentapod_sim.errors import ConfigError, ModelFileError
from pentapod_sim.plant.external_modes import load_modal_data
from pentapod_sim.plant.model import PlantModel
from pentapod_sim.scenario.files import read_scenario

ROOT = Path(__file__).resolve().parents[1]


def wrong_kinds(folder):
    """Files that are not plant models, and the words their error must hold."""
    text = folder / 'passwd'
    text.write_text('root:x:0:0:root:/root:/bin/bash\ndaemon:x:1:1::/usr/sbin\n')
    np.save(folder / 'one.npy', np.arange(3.0))
    (folder / 'one.npy').rename(folder / 'array.npz')
    np.savez(folder / 'objects.npz', header=np.array([{'a': 1}], dtype=object))
    np.savez(folder / 'plain.npz', a=np.ones(3))
    with zipfile.ZipFile(folder / 'other.npz', 'w') as archive:
        archive.writestr('notes.txt', 'hello')
    (folder / 'empty.npz').write_bytes(b'')
    (folder / 'elf.npz').write_bytes(b'\x7fELF\x02\x01\x01\x00' + bytes(100))
    (folder / 'cut.npz').write_bytes(b'PK\x03\x04' + bytes(40))
    return {text: "a text file starting 'root:x:0:0:root:/root:/bin/bash'",
            folder / 'array.npz': 'a single array (.npy)',
            folder / 'objects.npz': 'Python objects (never loaded)',
            folder / 'plain.npz': 'lacks header',
            folder / 'other.npz': 'has notes.txt',
            folder / 'empty.npz': 'an empty file',
            folder / 'elf.npz': "binary data starting b'\\x7fELF",
            folder / 'cut.npz': 'a damaged .npz archive',
            folder: 'Is a directory',
            folder / 'missing.npz': 'No such file'}


def test_a_plant_model_of_the_wrong_kind_is_one_line_naming_it(tmp_path):
    for path, words in wrong_kinds(tmp_path).items():
        with pytest.raises(ModelFileError) as err:
            PlantModel.load(path)
        text = str(err.value)
        assert words in text and str(path) in text and '\n' not in text, text
        assert 'pickle' not in text.lower() and 'numpy' not in text.lower(), text


def test_modal_data_of_the_wrong_kind_is_one_line(tmp_path):
    kinds = wrong_kinds(tmp_path)
    for name in ('array.npz', 'objects.npz', 'empty.npz', 'elf.npz', 'cut.npz'):
        with pytest.raises(ModelFileError) as err:
            load_modal_data(tmp_path / name)
        text = str(err.value)
        assert kinds[tmp_path / name] in text and '\n' not in text, text
        assert 'modal data' in text and 'pickle' not in text.lower()


def test_a_scenario_file_of_the_wrong_kind_is_one_line(tmp_path):
    binary = tmp_path / 'binary.yaml'
    binary.write_bytes(b'\x93NUMPY\x01\x00\xff\xfe')
    broken = tmp_path / 'broken.yaml'
    broken.write_text('plant:\n  ros__parameters: [1,\n')
    for path in (binary, broken, tmp_path / 'passwd'):
        if path.name == 'passwd':
            path.write_text('root:x:0:0:root:/root:/bin/bash\n')
        with pytest.raises(ConfigError) as err:
            read_scenario(path)
        assert str(path) in str(err.value) and '\n' not in str(err.value), str(err.value)


def test_a_cache_folder_that_is_a_file_is_one_line(tmp_path):
    blocker = tmp_path / 'models'
    blocker.write_text('not a folder')
    with pytest.raises(ModelFileError, match='cannot write plant model .*models') as err:
        demo_model(3).save(blocker / 'plant.npz')
    assert '\n' not in str(err.value)


@pytest.mark.ros
def test_the_plant_node_refuses_model_file_etc_passwd_in_one_line(tmp_path):
    """The issue's probe, as a user runs it: ``model_file:=/etc/passwd``."""
    out = subprocess.run(
        [sys.executable, '-m', 'pentapod_sim.nodes.plant_node', '--ros-args', '-p',
         'model_file:=/etc/passwd', '-p', 'steps:=5'], cwd=tmp_path,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),     # this checkout's code
        capture_output=True, text=True, timeout=120)
    assert out.returncode == 1, out.stdout + out.stderr
    lines = [x for x in out.stderr.splitlines() if x.strip()]
    assert lines == ["error: /etc/passwd is not a plant model (an .npz archive): it is a text "
                     "file starting 'root:x:0:0:root:/root:/bin/bash'"], lines
