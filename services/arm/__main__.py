from services.arm.service import main

main()
