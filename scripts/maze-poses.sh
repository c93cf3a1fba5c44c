# The maze's 16 start poses ("x,y,deg": room centres, four headings), shared by
# scripts/maze-coverage.sh and scripts/nav-compare.sh (sourced; POSES overrides it).
POSES=${POSES:-"0.875,0.875,0 10.675,10.675,180 0.875,10.675,270 10.675,0.875,90 \
5.075,5.075,0 6.475,6.475,180 3.675,7.875,90 7.875,3.675,270 3.675,0.875,90 \
7.875,2.275,180 2.275,9.275,0 9.275,7.875,270 6.475,10.675,0 0.875,6.475,90 \
10.675,5.075,180 5.075,3.675,0"}
