"""``--ray ADDRESS``: the forms Ray takes are accepted; a URL of another scheme is refused naming it, the
dashboard's http:// with the addresses Ray does take (no Ray needed: checked before Ray is imported)."""

import pytest
from checks import assert_one_line_error, assert_one_line_message

from tactile_manip.cli import main
from tactile_manip.cluster.connect import check_address


@pytest.mark.parametrize("address, expected", [
    (None, None), ("local", None), ("auto", "auto"), ("127.0.0.1:6379", "127.0.0.1:6379"),
    ("ray://127.0.0.1:10001", "ray://127.0.0.1:10001"), ("[::1]:6379", "[::1]:6379"),
    ("head.example:6379", "head.example:6379"),
])
def test_ray_addresses_are_accepted(address, expected):
    assert check_address(address) == expected


@pytest.mark.parametrize("url", ["http://127.0.0.1:6553", "https://127.0.0.1:8265", "HTTP://head:8265/"])
def test_dashboard_url_is_refused_with_the_addresses_ray_takes(url):
    with pytest.raises(ValueError) as e:
        check_address(url)
    host = url.split("//")[1].split(":")[0]
    assert_one_line_message(str(e.value), f"--ray: {url!r} is a URL of the Ray dashboard",
                            f"ray://{host}:10001", f"{host}:6379")


@pytest.mark.parametrize("url, scheme", [("grpc://127.0.0.1:6379", "grpc"), ("tcp://h:1", "tcp")])
def test_other_schemes_are_refused_by_name(url, scheme):
    with pytest.raises(ValueError, match=f"--ray: unknown scheme '{scheme}://' in {url!r}"):
        check_address(url)


def test_cli_names_the_dashboard_scheme_before_any_work(tmp_path, capsys):
    out = tmp_path / "d.npz"
    assert main(["simulate", "--scale", "0.005", "--ray", "http://127.0.0.1:6553", "--out", str(out)]) == 2
    assert_one_line_error(capsys.readouterr().err, "simulate", "is a URL of the Ray dashboard",
                          "ray://127.0.0.1:10001", "127.0.0.1:6379")
    assert not out.exists()
