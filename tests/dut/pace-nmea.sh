#!/bin/sh
# A recorded receiver played at its own rate: the NMEA log $1 (gpsd's capture format: `#`
# comment lines first) to stdout, one reporting cycle a second (each cycle starts with its GGA
# sentence), CRLF line ends. Give it to socat to have a receiver on a pty:
#   socat PTY,link=/tmp/gps,raw,echo=0 EXEC:"sh pace-nmea.sh telit-he910.log"
first=1
grep -v '^#' "$1" | tr -d '\r' | while IFS= read -r line; do
  case "$line" in
    *GGA,*) [ -n "$first" ] || sleep 1; first= ;;
  esac
  printf '%s\r\n' "$line"
done
