from robocal._program import run

run()
