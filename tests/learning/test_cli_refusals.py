"""train / export / evaluate never replace a run or a model unasked, and refuse foreign inputs in one line."""

import dataclasses
import zipfile

import numpy as np
import pytest
from checks import TORCH_MISSING, assert_one_line_error

torch = pytest.importorskip("torch", reason=TORCH_MISSING)

from tactile_manip.cli import main
from tactile_manip.data import load_dataset, save_dataset

TINY = 'preset = "small"\nepochs = 1\nbatch_size = 8\nlr = 3e-3\nthreads = 1\n'


@pytest.fixture(scope="module")
def run(tiny_data, tmp_path_factory):
    """One tiny training run (1 epoch) and its exported model, shared by the tests below."""
    tmp = tmp_path_factory.mktemp("refusals")
    (tmp / "tiny.toml").write_text(TINY)
    assert main(["train", "--config", str(tmp / "tiny.toml"), "--data", str(tiny_data), "--out", str(tmp / "run")]) == 0
    assert main(["export", "--checkpoint", str(tmp / "run" / "best.pt"), "--out", str(tmp / "m.onnx")]) == 0
    return tmp


def test_train_refuses_an_existing_run_without_resume_or_force(run, tiny_data, capsys):
    before = (run / "run" / "best.pt").read_bytes()
    capsys.readouterr()
    assert main(["train", "--config", str(run / "tiny.toml"), "--data", str(tiny_data), "--out", str(run / "run")]) == 2
    err = assert_one_line_error(capsys.readouterr().err, "train")
    assert "checkpoint.pt" in err and "--resume" in err and "--force" in err
    assert (run / "run" / "best.pt").read_bytes() == before


def test_resume_with_another_architecture_names_the_differing_fields(run, tiny_data, capsys):
    other = run / "other.toml"
    other.write_text(TINY.replace('"small"', '"compact"'))
    capsys.readouterr()
    assert main(["train", "--config", str(other), "--data", str(tiny_data), "--out", str(run / "run"),
                 "--resume"]) == 2
    err = assert_one_line_error(capsys.readouterr().err, "train")
    assert "another architecture" in err and "latent" in err and "->" in err


def test_init_from_a_missing_or_foreign_checkpoint_is_one_line_and_fine_tuning_runs(run, tiny_data, capsys):
    args = ["train", "--config", str(run / "tiny.toml"), "--data", str(tiny_data)]
    capsys.readouterr()
    assert main([*args, "--out", str(run / "ft0"), "--init", str(run / "nothing.pt")]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", "checkpoint not found")
    assert main([*args, "--out", str(run / "run"), "--init", str(run / "run" / "best.pt"), "--resume"]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", "give one of them")
    other = run / "other_init.toml"
    other.write_text(TINY.replace('"small"', '"compact"'))
    assert main(["train", "--config", str(other), "--data", str(tiny_data), "--out", str(run / "ft1"),
                 "--init", str(run / "run" / "best.pt")]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", "another architecture")
    assert main([*args, "--out", str(run / "ft2"), "--init", str(run / "run" / "best.pt")]) == 0
    assert (run / "ft2" / "best.pt").is_file()


def test_export_refuses_to_replace_a_model_without_force(run, capsys):
    model = run / "m.onnx"
    before = model.read_bytes()
    capsys.readouterr()
    assert main(["export", "--checkpoint", str(run / "run" / "best.pt"), "--out", str(model)]) == 2
    assert_one_line_error(capsys.readouterr().err, "export", "exists; pass --force")
    assert model.read_bytes() == before
    copy = run / "copy.onnx"
    copy.write_bytes(b"an older model")            # not a model export wrote: --force does not replace it
    assert main(["export", "--checkpoint", str(run / "run" / "best.pt"), "--out", str(copy), "--force"]) == 2
    assert_one_line_error(capsys.readouterr().err, "export", "is not an ONNX model written by tactile-manip export")
    assert copy.read_bytes() == b"an older model"
    copy.write_bytes(before)                        # an earlier export: --force replaces it
    assert main(["export", "--checkpoint", str(run / "run" / "best.pt"), "--out", str(copy), "--force"]) == 0
    assert not (run / "copy.onnx.partial").exists()


def _torch_dict(path):
    torch.save({"weights": torch.zeros(3)}, path)  # a torch file, but not our checkpoint
    return path


def _zip(path):
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("hello.txt", "not a checkpoint")
    return path


def _truncated(path, run):
    data = (run / "run" / "best.pt").read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


@pytest.mark.parametrize("kind,expected", [("truncated", "not a readable torch checkpoint"),
                                           ("foreign", "not a tactile_manip training checkpoint"),
                                           ("zip", "not a readable torch checkpoint"),
                                           ("text", "not a readable torch checkpoint")])
def test_export_of_a_file_that_is_not_our_checkpoint_is_one_line(kind, expected, run, tmp_path, capsys):
    path = tmp_path / f"{kind}.pt"
    {"truncated": lambda: _truncated(path, run), "foreign": lambda: _torch_dict(path), "zip": lambda: _zip(path),
     "text": lambda: path.write_text("hello")}[kind]()
    assert main(["export", "--checkpoint", str(path), "--out", str(tmp_path / "x.onnx")]) == 2
    assert_one_line_error(capsys.readouterr().err, "export", expected)
    assert not (tmp_path / "x.onnx").exists() and not (tmp_path / "x.onnx.partial").exists()


def test_evaluate_a_dataset_without_a_test_split_is_one_line(tiny_data, tmp_path, capsys):
    data = load_dataset(tiny_data)
    no_test = dataclasses.replace(data, split=np.where(data.split == "test", "val", data.split))
    path = save_dataset(tmp_path / "no_test.npz", no_test)
    assert main(["evaluate", "--data", str(path), "--out", str(tmp_path / "eval")]) == 2
    err = assert_one_line_error(capsys.readouterr().err, "evaluate")
    assert "has no test split" in err and "train, val" in err
    assert not (tmp_path / "eval").exists()


def test_inception_onnx_that_is_another_model_is_one_line(run, tiny_data, tmp_path, capsys):
    capsys.readouterr()
    assert main(["evaluate", "--data", str(tiny_data), "--out", str(tmp_path / "eval"),
                 "--inception-onnx", str(run / "m.onnx")]) == 2  # a SuperMag model, not an Inception network
    assert_one_line_error(capsys.readouterr().err, "evaluate", "not an Inception-v3 feature network")
    (tmp_path / "junk.onnx").write_bytes(b"\x00" * 64)
    assert main(["evaluate", "--data", str(tiny_data), "--out", str(tmp_path / "eval2"),
                 "--inception-onnx", str(tmp_path / "junk.onnx")]) == 2
    assert_one_line_error(capsys.readouterr().err, "evaluate", "not a readable ONNX model")


def test_export_refuses_an_image_share_for_an_image_model_or_outside_0_to_1(run, capsys):
    out = run / "share.onnx"
    assert main(["export", "--checkpoint", str(run / "run" / "best.pt"), "--out", str(out),
                 "--image-position-weight", "0.5"]) == 2
    assert_one_line_error(capsys.readouterr().err, "export", "for a contact model's checkpoint")
    with pytest.raises(SystemExit):  # argparse: usage and exit 2, before anything is read
        main(["export", "--checkpoint", str(run / "run" / "best.pt"), "--out", str(out),
              "--image-position-weight", "1.5"])
    assert "expected a share from 0 to 1, got '1.5'" in capsys.readouterr().err
    assert not out.exists()


def test_export_stores_what_an_image_model_averages_its_images_over(run, capsys):
    from tactile_manip.perception.reconstruct import read_metadata

    out = run / "turns.onnx"
    assert main(["export", "--checkpoint", str(run / "run" / "best.pt"), "--out", str(out),
                 "--image-symmetry", "rotations"]) == 0
    assert read_metadata(out)["image_symmetry"] == "rotations"
    with pytest.raises(SystemExit):  # argparse: usage and exit 2
        main(["export", "--checkpoint", str(run / "run" / "best.pt"), "--out", str(run / "x.onnx"),
              "--image-symmetry", "twice"])
    assert "invalid choice: 'twice'" in capsys.readouterr().err


def test_evaluate_refuses_to_replace_an_earlier_report_without_force(tiny_data, tmp_path, capsys):
    out = tmp_path / "eval"
    assert main(["evaluate", "--data", str(tiny_data), "--out", str(out)]) == 0
    (out / "results.json").write_text("{}")  # the earlier report, marked
    capsys.readouterr()
    assert main(["evaluate", "--data", str(tiny_data), "--out", str(out)]) == 2
    assert_one_line_error(capsys.readouterr().err, "evaluate", "results.json")
    assert (out / "results.json").read_text() == "{}"
    assert main(["evaluate", "--data", str(tiny_data), "--out", str(out), "--force"]) == 0
    assert (out / "results.json").read_text() != "{}"


@pytest.mark.parametrize("command", ["evaluate", "train"])
def test_a_folder_the_command_did_not_make_is_refused_even_with_force(command, run, tiny_data, tmp_path, capsys):
    """A user's folder holding a file of the very name the command writes (history.json, results.json) is not
    the command's to replace: one line, exit 2, the file untouched, with or without --force."""
    out = tmp_path / "mine"
    out.mkdir()
    name = {"evaluate": "results.json", "train": "history.json"}[command]
    (out / name).write_text("my notes")
    args = {"evaluate": ["evaluate", "--data", str(tiny_data), "--out", str(out)],
            "train": ["train", "--config", str(run / "tiny.toml"), "--data", str(tiny_data), "--out", str(out)]}[command]
    for extra in ([], ["--force"]):
        assert main([*args, *extra]) == 2
        assert_one_line_error(capsys.readouterr().err, command, str(out), "did not write", name)
        assert sorted(p.name for p in out.iterdir()) == [name] and (out / name).read_text() == "my notes"


def test_a_folder_of_another_command_is_refused(run, tiny_data, tmp_path, capsys):
    out = tmp_path / "eval"
    assert main(["evaluate", "--data", str(tiny_data), "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["train", "--config", str(run / "tiny.toml"), "--data", str(tiny_data), "--out", str(out),
                 "--force"]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", "a folder of tactile-manip evaluate")


def test_train_refuses_fewer_training_samples_than_one_batch(tiny_data, tmp_path, capsys):
    """An epoch takes whole batches only: 6 training samples at batch size 8 would train nothing."""
    data = load_dataset(tiny_data)
    train = np.flatnonzero(data.split == "train")
    split = data.split.copy()
    split[train[6:]] = "val"  # 6 training samples left
    save_dataset(tmp_path / "few.npz", dataclasses.replace(data, split=split))
    (tmp_path / "tiny.toml").write_text(TINY)
    capsys.readouterr()
    assert main(["train", "--config", str(tmp_path / "tiny.toml"), "--data", str(tmp_path / "few.npz"),
                 "--out", str(tmp_path / "run")]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", "6 samples", "batch_size = 8", "at most 6",
                          after_progress=True)
    assert not (tmp_path / "run").exists()  # refused before anything was written
