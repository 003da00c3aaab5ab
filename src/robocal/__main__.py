from robocal.cli.main import entry

entry()
