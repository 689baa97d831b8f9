"""Download the greenhouse row dataset from Kaggle (``kaggle`` package).

``import kaggle`` authenticates on import and, without credentials, prints a long sign-up notice
(older versions exit). So the credentials are looked up here first, and kaggle is imported only
when some exist. Tokens are never printed: messages name where a credential came from, not its value.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from data_tools.errors import CredentialsError, DownloadError, InputFileError

KAGGLE_DATASET = "sicongpan/greenhouse-multi-session-row-dataset"
HOW_TO = ("create an API token at https://www.kaggle.com/settings/api (\"Generate New Token\"), then "
          "either export KAGGLE_API_TOKEN=<token>, or save it to ~/.kaggle/access_token, or put the legacy "
          "kaggle.json in ~/.kaggle/ (chmod 600); KAGGLE_USERNAME + KAGGLE_KEY also work")


def _config_dirs() -> list[Path]:
    dirs = []
    if os.environ.get("KAGGLE_CONFIG_DIR"):
        dirs.append(Path(os.environ["KAGGLE_CONFIG_DIR"]))
    home = Path.home()
    dirs += [home / ".kaggle", Path(os.environ.get("XDG_CONFIG_HOME") or home / ".config") / "kaggle"]
    return dirs


def find_kaggle_credentials() -> str:
    """Where usable Kaggle credentials are (a description, never the secret); raises
    CredentialsError with set-up instructions when there are none."""
    if os.environ.get("KAGGLE_API_TOKEN", "").strip():
        return "environment variable KAGGLE_API_TOKEN"
    if os.environ.get("KAGGLE_USERNAME", "").strip() and os.environ.get("KAGGLE_KEY", "").strip():
        return "environment variables KAGGLE_USERNAME / KAGGLE_KEY"
    for folder in _config_dirs():
        for name in ("access_token", "access_token.txt"):
            token = folder / name
            if token.is_file() and token.read_text(encoding="utf-8", errors="replace").strip():
                return str(token)
        if (folder / "credentials.json").is_file():  # `kaggle auth login` (OAuth)
            return str(folder / "credentials.json")
        legacy = folder / "kaggle.json"
        if legacy.is_file():
            try:
                values = json.loads(legacy.read_text(encoding="utf-8"))
            except (OSError, UnicodeDecodeError, json.JSONDecodeError):
                raise CredentialsError(f"{legacy}: not valid JSON; expected "
                                       '{"username": "...", "key": "..."} - ' + HOW_TO) from None
            if not (isinstance(values, dict) and values.get("username") and values.get("key")):
                raise CredentialsError(f"{legacy}: needs both \"username\" and \"key\"; " + HOW_TO)
            return str(legacy)
    raise CredentialsError("no Kaggle credentials found: " + HOW_TO)


def download_greenhouse(output="data/greenhouse_raw", dataset: str = KAGGLE_DATASET, *, unzip: bool = True,
                        force: bool = False, log=print) -> Path:
    """Download (and unzip) the Kaggle dataset into ``output``; returns the folder.

    The kaggle client shows its own progress bar and skips a download that is already complete
    (unless ``force``).
    """
    source = find_kaggle_credentials()
    log(f"using Kaggle credentials from {source}")
    output = Path(output)
    try:
        output.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputFileError(f"{output}: cannot create the download folder ({exc.strerror or exc})") from None
    try:
        from kaggle.api.kaggle_api_extended import KaggleApi

        api = KaggleApi()
        api.authenticate()
        api.dataset_download_files(dataset, path=str(output), unzip=unzip, force=force, quiet=False)
    except SystemExit:  # kaggle exits when it rejects the credentials
        raise CredentialsError(f"Kaggle rejected the credentials from {source}; " + HOW_TO) from None
    except Exception as exc:  # network and HTTP errors come as many types from requests/kagglesdk
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if "401" in reason or "403" in reason:
            raise CredentialsError(f"Kaggle refused access with the credentials from {source} ({reason}); "
                                   + HOW_TO) from None
        raise DownloadError(f"Kaggle download of {dataset} failed ({reason}): offline? Download it in a "
                            f"browser from https://www.kaggle.com/datasets/{dataset} and unzip it into "
                            f"{output}") from None
    return output
