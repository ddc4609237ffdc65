from services.registration.service import main

main()
