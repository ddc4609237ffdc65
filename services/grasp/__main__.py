from services.grasp.service import main

main()
