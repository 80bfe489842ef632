"""Where the Hydra configs are: the repository's ``conf/`` or the installed copy.

The configs live in the top-level ``conf/`` folder of the repository (``conf/config.yaml``,
``conf/dataset/``, ``conf/experiment/``, ``conf/defaust/``, ``conf/hydra/launcher/``).
An install from a wheel or ``pip install .`` ships the same files as package data of
``harness.conf`` (``site-packages/harness/conf/``, see ``pyproject.toml``), where
``Path(__file__).parents[1] / "conf"`` would point into ``site-packages``.
:func:`config_dir` finds whichever copy applies, by path; :mod:`eval.app`,
:mod:`eval.sweeps.sweep_command` and :mod:`defaust.cli` use it for Hydra's ``config_path``,
:mod:`harness.method_registry` for the method definitions of ``conf/method/``.
"""
from __future__ import annotations

from pathlib import Path

from sshade.errors import SShaDeError

__all__ = ["config_dir"]

_REPO_ROOT = Path(__file__).resolve().parents[1]


def _package_conf() -> Path:
    """``conf/`` of this installed package (the package data ``harness.conf``, pyproject.toml)."""
    return Path(__file__).resolve().parent / "conf"


def _source_conf() -> Path | None:
    """``conf/`` of the source checkout this package was imported from, if any."""
    conf = _REPO_ROOT / "conf"
    # pyproject.toml beside conf/ marks a checkout (so an unrelated site-packages/conf is ignored)
    if (conf / "config.yaml").is_file() and (_REPO_ROOT / "pyproject.toml").is_file():
        return conf
    return None


def config_dir(sub: str = "") -> str:
    """Absolute path of the Hydra config folder (or of its subfolder ``sub``).

    The repository's ``conf/`` when running from a source checkout (plain or editable
    install), otherwise the ``harness/conf/`` package data of an installed wheel.

    Parameters
    ----------
    sub : str
        A folder inside ``conf/``, e.g. ``"defaust"`` for the DeFAUST builder's configs;
        ``""`` for ``conf/`` itself.

    Returns
    -------
    str
        The folder, absolute (Hydra's ``config_path`` / ``initialize_config_dir`` take it as is).

    Raises
    ------
    SShaDeError if neither copy of the configs is there or ``sub`` is not a folder in it
    (a broken install).

    Examples
    --------
    >>> from harness.confdir import config_dir
    >>> Path(config_dir(), "config.yaml").is_file()
    True
    >>> Path(config_dir("defaust"), "preset", "ci.yaml").is_file()
    True
    """
    base = _source_conf()
    if base is None:
        base = _package_conf()
        if not (base / "config.yaml").is_file():
            raise SShaDeError(f"Hydra configs not found: neither {_REPO_ROOT / 'conf'} (source "
                              f"checkout) nor {base} (installed package data); reinstall sshade")
    d = (base / sub) if sub else base
    if not d.is_dir():
        raise SShaDeError(f"no config folder {sub!r} in {base}")
    return str(d.resolve())
