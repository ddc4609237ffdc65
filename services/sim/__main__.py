from services.sim.service import main

main()
