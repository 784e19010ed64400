from detection_eval.study.cli import main

main()
