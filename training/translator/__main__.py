from training.translator.train import main

main()
