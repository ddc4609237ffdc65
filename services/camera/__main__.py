from services.camera.service import main

main()
