"""The task registry (``tasks/training/registry.py``): every task declares itself once in its own folder
(``task.py``), is found through the ``skeleton_mamba.tasks`` entry points, and the machinery names no task.

A task in another distribution is found the same way: ``tests/training/test_external_task.py``. A plugin that
does not load, is malformed or collides with a built-in task (or another plugin) is skipped with one warning
line, and ``sm --help`` and ``sm recipes`` keep working: the second half of this file, with fake distributions
written to a temporary folder put on ``sys.path``.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import os
import re
import subprocess
import sys
from importlib.metadata import EntryPoint
from pathlib import Path

import pytest

from skeleton_mamba.tasks.training import cli, registry
from skeleton_mamba.tasks.training.contract_links import contract_class_of, contract_links
from skeleton_mamba.tasks.training.lightning_cli import import_task_modules, registered_links
from skeleton_mamba.tasks.training.registry import Command, TaskSpec, registered_tasks

tomllib = pytest.importorskip("tomllib", reason="tomllib is in the standard library from Python 3.11")

REPO = Path(__file__).resolve().parents[2]
ENTRY_POINTS = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["entry-points"]
TASKS = tuple(
    ENTRY_POINTS[registry.ENTRY_POINT_GROUP]
)  # this repository's tasks, as pyproject registers them
# the tasks whose declarations are pinned below
KNOWN = ("egodance", "qean", "recognition", "stream", "text2motion")


def _load(target: str):
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)


def test_the_repository_tasks_register_themselves_through_their_entry_points():
    specs = {spec.name: spec for spec in registered_tasks()}
    assert set(specs) >= set(TASKS) >= set(KNOWN)  # (and any task another installed distribution adds)
    assert ENTRY_POINTS[registry.ENTRY_POINT_GROUP] == {
        t: f"skeleton_mamba.tasks.{t}.task:TASK" for t in TASKS
    }
    on_disk = {p.parent.name for p in (REPO / "tasks").glob("*/task.py")}
    assert on_disk == set(TASKS)  # a task folder without its entry point is never found
    for name, spec in ((t, specs[t]) for t in TASKS):
        assert spec.package == f"skeleton_mamba.tasks.{name}"
        assert spec.modules == (f"{spec.package}.module", f"{spec.package}.data")
        for command in [*spec.commands.values(), *(c for v in spec.variants.values() for c in v.values())]:
            assert callable(_load(command.parser))  # torch-free parser modules
            module, function = command.run.split(":")
            assert importlib.util.find_spec(module) is not None, command.run
        for network, target in spec.networks.items():
            assert callable(_load(target)), (network, target)
    assert {s.title for s in specs.values()} == {
        "EgoDance",
        "QEAN",
        "recognition",
        "streaming",
        "text-to-motion",
    }
    imported = import_task_modules()
    assert [m for m in imported if m.startswith("skeleton_mamba.")] == [
        m for t in sorted(TASKS) for m in specs[t].modules
    ]


def test_sm_takes_its_task_commands_and_variants_from_the_registrations():
    by_task = {spec.name: set(spec.commands) for spec in registered_tasks()}
    assert {t: by_task[t] for t in KNOWN} == {
        "egodance": {"make-ego", "dance"},
        "qean": set(),
        "recognition": {"prepare", "ensemble"},
        "stream": {"stream", "export-web"},
        "text2motion": {"generate", "convert"},
    }
    assert set(cli.COMMANDS) == set(cli.MACHINERY_COMMANDS).union(*by_task.values())
    assert cli.TASK_VARIANTS["stream"]["recognition"].run == "skeleton_mamba.tasks.recognition.online:main"


PAIRS = [  # (data module, module) of the recipes
    ("recognition.data.RecognitionDataModule", "recognition.module.ActionRecognitionModule"),
    ("recognition.data.SyntheticRecognitionDataModule", "recognition.module.ActionRecognitionModule"),
    ("egodance.data.EgoDanceDataModule", "egodance.module.EgoDanceModule"),
    ("egodance.data.SyntheticEgoDanceDataModule", "egodance.module.EgoDanceModule"),
    ("qean.data.AISTPPDanceDataModule", "qean.module.QEANModule"),
    ("stream.data.StreamDanceDataModule", "stream.module.StreamDanceModule"),
    ("text2motion.data.HumanML3DDataModule", "text2motion.module.TextToMotionModule"),
    ("text2motion.data.SyntheticTextMotionDataModule", "text2motion.module.TextToMotionModule"),
    ("text2motion.evaluator_data.T2MEvaluatorDataModule", "text2motion.evaluator_module.T2MEvaluatorModule"),
]


def _class(path: str) -> type:
    module, _, name = f"skeleton_mamba.tasks.{path}".rpartition(".")
    return getattr(importlib.import_module(module), name)


def test_the_links_derived_from_the_contracts_are_those_the_machinery_listed_before():
    """The data-to-model links, now read off each data module's contract and its model's arguments, are the
    14 of the former single list (all but ``batch_size`` on the modules without that argument)."""
    links = {
        link
        for data, module in PAIRS
        for link in contract_links(contract_class_of(_class(data)), _class(module))
    }
    assert links == {
        ("num_classes", "num_classes"), ("skeleton", "skeleton"), ("in_channels", "in_channels"),
        ("batch_size", "batch_size"), ("image_size", "image_size"), ("fps", "fps"),
        ("music_dim", "network.music_dim"), ("music_dim", "music_dim"),
        ("seed_frames", "network.seed_frames"), ("music_frames", "network.music_frames"),
        ("predict_frames", "network.predict_frames"), ("generate_frames", "generate_frames"),
        ("window", "window"), ("canonicalize_init_head", "canonicalize_init_head"),
    }  # fmt: skip
    assert set(registered_links()) == links  # what sm fit links: every registered pair's, each once
    qean = contract_links(contract_class_of(_class(PAIRS[4][0])), _class(PAIRS[4][1]))
    assert ("seed_frames", "network.seed_frames") in qean and (
        "music_cache_dir",
        "music_cache_dir",
    ) not in qean


def test_reading_the_registry_imports_no_torch():
    code = (
        "import sys; from skeleton_mamba.tasks.training.registry import registered_tasks; "
        "n = len(registered_tasks()); print(n, [m for m in ('torch', 'lightning') if m in sys.modules])"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.stdout.split(None, 1) == [str(len(TASKS)), "[]\n"], done.stderr


def _strings_and_imports(path: Path) -> list[tuple[int, str]]:
    """(line, text) of every import and every string constant but docstrings in ``path``."""
    tree = ast.parse(path.read_text())
    docstrings = {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
        and node.body
        and isinstance(node.body[0], ast.Expr)
        and isinstance(node.body[0].value, ast.Constant)
    }
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            found.append((node.lineno, node.module))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
            found.append((node.lineno, node.value))
    return found


def test_the_machinery_names_no_task():
    """No import, and no string but docstrings, in ``tasks/training/`` names a task's package, title or
    network: what the machinery knows of a task comes from its registration."""
    specs = registered_tasks()
    packages = [spec.package for spec in specs]
    words = {spec.title for spec in specs} | {n for spec in specs for n in spec.networks}
    offenders = []
    for path in sorted((REPO / "tasks" / "training").rglob("*.py")):
        for line, text in _strings_and_imports(path):
            if any(p in text for p in packages) or text in words:
                offenders.append(f"{path.relative_to(REPO)}:{line} {text!r}")
    assert not offenders, "\n".join(offenders)


GROUP = registry.ENTRY_POINT_GROUP
# some of the built-in commands: the machinery's (fit, recipes, ...), the built-in tasks' (stream, ...)
BUILTIN_COMMANDS = {
    "fit",
    "test",
    "predict",
    "recipes",
    "export-onnx",
    "stream",
    "dance",
    "prepare",
    "generate",
}
TASK_MODULE = "from skeleton_mamba.tasks.training.registry import Command, TaskSpec\n"


def _spec(name: str, **fields: str) -> str:
    """The source of a plugin module whose ``TASK`` is a TaskSpec named ``name``, titled ``name`` and of
    package ``<name>_pkg`` unless the fields (each given as source text) say otherwise."""
    fields = {"title": repr(name), "package": repr(f"{name}_pkg"), **fields}
    args = "".join(f", {key}={value}" for key, value in fields.items())
    return f"{TASK_MODULE}TASK = TaskSpec({name!r}{args})\n"


def _write_distribution(site: Path, dist: str, points: dict[str, str], modules: dict[str, str]) -> None:
    """A fake installed distribution ``dist`` in ``site``: its metadata, its entry points in :data:`GROUP`
    and its top-level modules (name -> source)."""
    info = site / f"{dist.replace('-', '_')}-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 1.0\n")
    lines = "".join(f"{name} = {value}\n" for name, value in points.items())
    (info / "entry_points.txt").write_text(f"[{GROUP}]\n{lines}")
    for name, source in modules.items():
        (site / f"{name}.py").write_text(source)


@pytest.fixture
def site(tmp_path, monkeypatch):
    """A folder on ``sys.path`` for fake distributions; the registry is read afresh in the test, and again
    after it (without them), and their modules are forgotten."""
    folder = tmp_path / "site"
    folder.mkdir()
    before = set(sys.modules)
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.setattr(cli, "apply_thread_defaults", lambda: None)  # no process-wide settings in-process
    monkeypatch.setattr(cli, "silence_library_noise", lambda: None)
    registry.registered_tasks.cache_clear()
    cli.command_table.cache_clear()
    yield folder
    registry.registered_tasks.cache_clear()
    cli.command_table.cache_clear()
    for name in set(sys.modules) - before:
        if (folder / f"{name.split('.')[0]}.py").exists():
            del sys.modules[name]


def _listed(usage: str) -> set[str]:
    """The command names ``sm --help`` lists."""
    commands = usage.split("\ncommands:\n", 1)[1].split("\n\n", 1)[0]
    return {line.split()[0] for line in commands.splitlines()}


def _sm_still_works(capsys) -> tuple[set[str], list[str]]:
    """Run ``sm --help`` and ``sm recipes`` in this process: both exit 0 and list the built-ins, and only the
    first prints warnings (the registry is read once). Returns the commands listed and the warning lines."""
    assert cli.main(["--help"]) == 0
    out, err = capsys.readouterr()
    listed = _listed(out)
    assert listed >= BUILTIN_COMMANDS, out
    warnings = err.splitlines()
    assert all(line.startswith("sm: warning: ") for line in warnings), err
    assert cli.main(["recipes"]) == 0
    out, err = capsys.readouterr()
    assert err == ""  # warned once per process
    assert out.startswith("egodance.yaml ") and "\nntu60.yaml " in out
    assert {spec.name for spec in registered_tasks()} >= set(TASKS)
    return listed, warnings


def _skipped(point: str, dist: str) -> str:
    return f"sm: warning: task plugin skipped: entry point {point} (distribution {dist}, group {GROUP}): "


BROKEN = {  # case -> (source of module plug_<case>, what the warning says after the entry point)
    "raises on import": ("raise RuntimeError('plugin broke\\non two lines')\n", "does not load "
                         "(RuntimeError: plugin broke on two lines)"),
    "missing module": (None, "does not load (ModuleNotFoundError: No module named 'plug_missing_module')"),
    "SystemExit(0) at import": ("import sys\nsys.exit(0)\n", "does not load (SystemExit: 0)"),
    "SystemExit() at import": ("raise SystemExit\n", "does not load (SystemExit)"),
    "a BaseException at import": ("raise GeneratorExit('odd')\n", "does not load (GeneratorExit: odd)"),
    "wrong type": ("TASK = ('not', 'a', 'spec')\n", "names a tuple, not a TaskSpec"),
    "a class, not an instance": (f"{TASK_MODULE}TASK = TaskSpec\n", "names a type, not a TaskSpec"),
    "name differs": (_spec("plug"), "its TaskSpec is named 'plug'"),
    "modules a list": (_spec("plug", modules="['plug_pkg.module']"), "its modules are ['plug_pkg.module'], "
                       "not a tuple of module names (str)"),
    "modules not str": (
        _spec("plug", modules="(3,)"), "its modules are (3,), not a tuple of module names (str)"
    ),
    "commands a list": (_spec("plug", commands="[]"), "commands is a list, not a mapping of name -> Command"),
    "command a str": (_spec("plug", commands="{'go': 'plug_pkg.cli:main'}"),
                      "commands is not a mapping of name -> Command (at 'go': 'plug_pkg.cli:main')"),
    "command name an option": (_spec("plug", commands="{'--help': Command('plug_pkg.cli:main', 'x')}"),
                               "commands is not a mapping of name -> Command (at '--help': "
                               "Command(run='plug_pkg.cli:main', help='x', parser=None))"),
    "command run not a target": (_spec("plug", commands="{'go': Command('plug_pkg.cli.main', 'go')}"),
                                 "commands is not a mapping of name -> Command (at 'go': "
                                 "Command(run='plug_pkg.cli.main', help='go', parser=None))"),
    "variants not nested": (_spec("plug", variants="{'stream': Command('plug_pkg.cli:main', 'x')}"),
                            "variants['stream'] is a Command, not a mapping of value -> Command"),
    "network target an int": (_spec("plug", networks="{'PlugNet': 3}"),
                              "networks is not a mapping of class name -> target (at 'PlugNet': 3)"),
    "title not str": (_spec("plug", title="None"), "its title is None, not a valid str"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_a_broken_plugin_is_skipped_with_one_warning_and_sm_keeps_working(site, capsys, case):
    source, reason = BROKEN[case]
    module = "plug_" + re.sub(r"\W+", "_", case).strip("_").lower()
    point = "other" if case == "name differs" else "plug"
    _write_distribution(
        site, "plug-dist", {point: f"{module}:TASK"}, {} if source is None else {module: source}
    )
    listed, warnings = _sm_still_works(capsys)
    assert warnings == [_skipped(f"{point} = {module}:TASK", "plug-dist") + reason]
    assert point not in {spec.name for spec in registered_tasks()} and "plug" not in listed


def test_ctrl_c_while_a_plugin_loads_is_sm_s_interruption_not_a_plugin_failure(site, capsys):
    _write_distribution(
        site, "slow-dist", {"slow": "plug_slow:TASK"}, {"plug_slow": "raise KeyboardInterrupt\n"}
    )
    assert cli.main(["--help"]) == 130
    assert capsys.readouterr() == ("", "sm: interrupted\n")


CLASHES = {  # case -> (the plugin's TaskSpec fields, what its warning says)
    "task name of a built-in": (
        "stream", {}, "task name 'stream' is taken by the built-in task 'stream'"
    ),
    "package of a built-in": (
        "plug", {"package": "'skeleton_mamba.tasks.stream.plug'"},
        "package 'skeleton_mamba.tasks.stream.plug' overlaps 'skeleton_mamba.tasks.stream' of the built-in "
        "task 'stream'",
    ),
    "command of a built-in task": (
        "plug", {"commands": "{'dance': Command('plug_pkg.cli:main', 'hijacked')}"},
        "command 'dance' is taken by the built-in task 'egodance'",
    ),
    "machinery command fit": (
        "plug", {"commands": "{'fit': Command('plug_pkg.cli:main', 'hijacked')}"},
        "command 'fit' is taken by a built-in sm command",
    ),
    "machinery command recipes": (
        "plug", {"commands": "{'recipes': Command('plug_pkg.cli:main', 'hijacked')}"},
        "command 'recipes' is taken by a built-in sm command",
    ),
    "registered variant": (
        "plug", {"variants": "{'stream': {'recognition': Command('plug_pkg.cli:main', 'hijacked')}}"},
        "variant 'sm stream --task recognition' is taken by the built-in task 'recognition'",
    ),
    "a built-in command's own --task value": (
        "plug", {"variants": "{'stream': {'dance': Command('plug_pkg.cli:main', 'hijacked')}}"},
        "variant 'sm stream --task dance' is taken by the built-in task 'stream'",
    ),
    "network": (
        "plug", {"networks": "{'StreamDancer': 'plug_pkg.graphs:specs'}"},
        "network 'StreamDancer' is taken by the built-in task 'stream'",
    ),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(CLASHES))
def test_a_plugin_colliding_with_a_built_in_is_refused_and_the_built_in_kept(site, capsys, case):
    name, fields, reason = CLASHES[case]
    _write_distribution(
        site, "hijack-dist", {name: "plug_hijack:TASK"}, {"plug_hijack": _spec(name, **fields)}
    )
    listed, warnings = _sm_still_works(capsys)
    assert warnings == [_skipped(f"{name} = plug_hijack:TASK", "hijack-dist") + reason]
    builtins = {spec.name: spec for spec in registered_tasks()}
    assert builtins["stream"].package == "skeleton_mamba.tasks.stream"  # the built-in, not the plugin
    assert len(registered_tasks()) == len(TASKS) and "plug" not in builtins
    commands, variants = cli.command_table()
    assert (
        commands["fit"] == cli.MACHINERY_COMMANDS["fit"]
        and commands["recipes"].help == "list the packaged recipes"
    )
    assert commands["dance"] == builtins["egodance"].commands["dance"]
    assert variants == {"stream": {"recognition": builtins["recognition"].variants["stream"]["recognition"]}}
    assert [spec.name for spec in builtins.values() if "StreamDancer" in spec.networks] == ["stream"]


def test_of_two_colliding_plugins_the_later_is_refused_naming_both(site, capsys):
    cli_module = "def main(argv):\n    return 0\n"
    first = _spec("alpha", commands="{'wave': Command('plug_wave_cli:main', 'wave a hand')}")
    second = _spec(
        "beta",
        commands="{'wave': Command('plug_wave_cli:main', 'hijacked'), "
        "'nod': Command('plug_wave_cli:main', 'n')}",
        networks="{'BetaNet': 'plug_wave_cli:main'}",
    )
    # the later in name order is refused, whatever the order of the distributions on the path
    _write_distribution(site, "zz-first", {"alpha": "plug_alpha:TASK"}, {"plug_alpha": first})
    _write_distribution(site, "aa-second", {"beta": "plug_beta:TASK"}, {"plug_beta": second})
    (site / "plug_wave_cli.py").write_text(cli_module)
    listed, warnings = _sm_still_works(capsys)
    owner = f"task 'alpha' (entry point alpha = plug_alpha:TASK (distribution zz-first, group {GROUP}))"
    assert warnings == [
        _skipped("beta = plug_beta:TASK", "aa-second") + f"command 'wave' is taken by {owner}"
    ]
    assert {"wave"} <= listed and "nod" not in listed  # the refused plugin is left out whole
    assert cli.command_table()[0]["wave"].help == "wave a hand"
    assert [s.name for s in registered_tasks() if s.name in ("alpha", "beta")] == ["alpha"]


def test_a_sound_plugin_is_merged_beside_the_built_ins(site, capsys):
    spec = _spec(
        "gesture",
        modules="('plug_gesture_pkg.module',)",
        package="'plug_gesture_pkg'",
        commands="{'wave': Command('plug_gesture:main', 'wave a hand')}",
        variants="{'stream': {'gesture': Command('plug_gesture:main', 'online gestures')}}",
        networks="{'GestureNet': 'plug_gesture:main'}",
    )
    _write_distribution(
        site,
        "gesture-dist",
        {"gesture": "plug_gesture:TASK"},
        {"plug_gesture": spec + "def main(argv):\n    return 0\n"},
    )
    listed, warnings = _sm_still_works(capsys)
    assert warnings == [] and "wave" in listed
    assert cli.command_table()[1]["stream"]["gesture"].help == "online gestures"
    assert (
        cli.command_table()[1]["stream"]["recognition"].run == "skeleton_mamba.tasks.recognition.online:main"
    )
    assert cli.main(["wave"]) == 0


@pytest.mark.parametrize("body", ["raise RuntimeError('boom')", "import sys\nsys.exit(0)"])
def test_a_plugins_module_that_fails_to_import_leaves_the_built_in_recipes_working(site, capsys, body):
    from skeleton_mamba.tasks.training.lightning_cli import import_task_modules

    _write_distribution(
        site,
        "broken-modules",
        {"brokenmods": "plug_brokenmods:TASK"},
        {
            "plug_brokenmods": _spec("brokenmods", modules="('plug_brokenmods_module',)", package="'plug_x'"),
            "plug_brokenmods_module": body + "\n",
        },
    )
    imported = import_task_modules()
    assert "plug_brokenmods_module" not in imported
    assert "skeleton_mamba.tasks.recognition.module" in imported
    err = capsys.readouterr().err
    warning = [line for line in err.splitlines() if "plug_brokenmods_module" in line]
    assert len(warning) == 1 and warning[0].startswith("sm: warning: task plugin 'brokenmods'"), err
    assert ("RuntimeError: boom" if "boom" in body else "SystemExit") in warning[0]


def test_unreadable_entry_point_metadata_skips_that_distribution_only(site, capsys):
    _write_distribution(site, "bad-meta", {}, {})
    (site / "bad_meta-1.0.dist-info" / "entry_points.txt").write_text(f"[{GROUP}]\nno equals sign here\n")
    good = (
        _spec("gesture", commands="{'wave': Command('plug_meta:main', 'wave')}")
        + "def main(argv):\n    return 0\n"
    )
    _write_distribution(site, "good-meta", {"gesture": "plug_meta:TASK"}, {"plug_meta": good})
    listed, warnings = _sm_still_works(capsys)
    assert len(warnings) == 1 and warnings[0].startswith(
        "sm: warning: distribution bad-meta: its entry points "
    ), warnings
    assert "wave" in listed


def test_entry_points_without_a_distribution_are_plugins_named_as_unknown():
    """Entry points whose distribution is not known (made here by hand) are all plugins: of two with one
    command, the later in name order is refused, and the line names both."""
    points = [EntryPoint("other", f"{HERE}:OTHER_GO", GROUP), EntryPoint("demo", f"{HERE}:SPEC", GROUP)]
    specs, refusals = registry.read_registry(points)
    assert specs == (SPEC,)
    assert refusals == [
        f"task plugin skipped: entry point other = {HERE}:OTHER_GO (distribution unknown, group {GROUP}): "
        f"command 'go' is taken by task 'demo' (entry point demo = {HERE}:SPEC (distribution unknown, group "
        f"{GROUP}))"
    ]


HERE = __name__  # the entry points above name objects of this module
SPEC = TaskSpec("demo", "demo", "demo_pkg", commands={"go": Command("demo_pkg.cli:main", "go")})
OTHER_GO = TaskSpec("other", "other", "other_pkg", commands={"go": Command("other_pkg.cli:main", "go")})


PLUGINS = {  # point -> (module, source, warning): broken plugins for the fresh ``sm`` processes below
    "boom": ("plug_boom", "raise RuntimeError('boom')\n", "does not load (RuntimeError: boom)"),
    "quit": ("plug_quit", "import sys\nsys.exit(0)\n", "does not load (SystemExit: 0)"),
    "fitter": ("plug_fitter", _spec("fitter", commands="{'fit': Command('plug_fitter:main', 'x')}"),
               "command 'fit' is taken by a built-in sm command"),
    "dancer": ("plug_dancer", _spec("dancer", networks="{'StreamDancer': 'plug_dancer:specs'}"),
               "network 'StreamDancer' is taken by the built-in task 'stream'"),
}  # fmt: skip


def test_sm_in_a_fresh_process_survives_broken_plugins_and_reads_them_only_when_run(tmp_path):
    """``sm`` as a user runs it, with plugins that raise, exit 0 at import, take ``fit`` or a built-in
    network: every command still answers (a plugin's exit is not ``sm``'s), with one warning per plugin,
    no traceback, and importing the command table reads no plugin."""
    site = tmp_path / "site"
    for point, (module, source, _) in PLUGINS.items():
        _write_distribution(site, f"{point}-dist", {point: f"{module}:TASK"}, {module: source})
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    code = (
        "import sys; from skeleton_mamba.tasks.training import cli, registry; "
        "print('read at import:', registry.registered_tasks.cache_info().currsize, flush=True); "
        "sys.exit(cli.main(sys.argv[1:]))"
    )
    expected = sorted(
        _skipped(f"{point} = {module}:TASK", f"{point}-dist") + reason
        for point, (module, _, reason) in PLUGINS.items()
    )
    runs = [
        (["-c", code, "--help"], 0, "read at import: 0\nsm "),
        (["-c", code, "recipes"], 0, "read at import: 0\negodance.yaml "),
        (["-c", code, "no-such-command"], 2, "read at import: 0\n"),
        (["-m", "skeleton_mamba.tasks", "fit", "--recipe", "recognition_synthetic.yaml", "--print_config"], 0,
         "# skeleton_mamba=="),
    ]  # fmt: skip
    for args, exit_code, starts in runs:
        done = subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=300, env=env)
        assert done.returncode == exit_code, done.stderr
        assert done.stdout.startswith(starts), done.stdout[:300]
        warnings = [line for line in done.stderr.splitlines() if line.startswith("sm: warning: ")]
        assert sorted(warnings) == expected, done.stderr
        assert "Traceback" not in done.stderr
        if "--help" in args:
            assert _listed(done.stdout) >= BUILTIN_COMMANDS
        if "fit" in args:
            assert "class_path: skeleton_mamba.tasks.recognition." in done.stdout
