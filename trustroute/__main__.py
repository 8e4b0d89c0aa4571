from trustroute.harness.cli import main

main()
